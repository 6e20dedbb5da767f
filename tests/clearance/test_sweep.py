"""One-at-a-time sweeps (`fahv clearance sweep`): their points, a short sweep of Case 1's
campaign end to end, and the comparison with a campaign's PAWN attribution."""

import json

import numpy as np
import pytest

from fahv.campaign.attribution import Attribution, Driver
from fahv.campaign.spec import load_campaign
from fahv.clearance.space import SearchSpace
from fahv.clearance.sweep import Sweep, sweep_points
from fahv.clearance.sweep_report import sweep_lines
from fahv.cli import main
from fahv.errors import CampaignError
from fahv.sil.workspace import ROOT

CAMPAIGN = str(ROOT / "offline_design/campaigns/case1.yaml")


@pytest.fixture(scope="module")
def space():
    c = load_campaign(CAMPAIGN)
    return SearchSpace.of(c.data, c.run_spec.data)


def test_each_sweep_moves_its_input_alone_from_bound_to_bound(space):
    centre, plan = sweep_points(space, ["s.m", "fault.loss"], 5)
    lo, hi = np.array(space.bounds).T
    np.testing.assert_allclose(centre, 0.5 * (lo + hi), rtol=0, atol=0)
    for name, values, X in plan:
        j = space.names.index(name)
        assert X.shape == (5, len(space.names))
        np.testing.assert_allclose(X[:, j], np.linspace(lo[j], hi[j], 5), rtol=0, atol=0)
        others = np.delete(X, j, axis=1)
        assert np.array_equal(others, np.repeat(np.delete(centre, j)[None], 5, axis=0))
        assert values[0] == lo[j] and values[-1] == hi[j]


def test_unknown_inputs_and_too_few_points_are_refused_naming_them(space):
    with pytest.raises(CampaignError, match=r"--input s\.mass: not a dispersed value .*s\.m, "):
        sweep_points(space, ["s.mass"], 5)
    with pytest.raises(CampaignError, match="--points 2: a sweep needs at least 3"):
        sweep_points(space, ["s.m"], 2)


def test_a_short_sweep_writes_each_inputs_margins_table_and_figure(tmp_path, capsys):
    """Case 1's campaign, the mass and the loss over 3 values each, 5 s runs: the
    mass moves the attitude margin (a light vehicle pitches more), a loss whose onset is
    at mid-range (the onset's centre, 125 s) cannot act within 5 s."""
    out = tmp_path / "sweep"
    code = main(["clearance", "sweep", CAMPAIGN, "--input", "s.m", "--input", "fault.loss",
                 "--points", "3", "--requirement", "attitude", "--duration", "5",
                 "--workers", "1", "--out", str(out)])  # fmt: skip
    assert code == 0
    man = json.loads((out / "campaign.json").read_text())
    assert man["kind"] == "sweep" and [e["name"] for e in man["inputs"]] == ["s.m", "fault.loss"]
    m_mass = np.array(man["inputs"][0]["margins"]["attitude"])
    m_loss = np.array(man["inputs"][1]["margins"]["attitude"])
    assert np.all((0.0 < m_mass) & (m_mass < 0.5)), m_mass  # 5 s of Case 1: 0.1-0.45 deg
    assert np.ptp(m_mass) > 1e-3  # the mass moves it
    assert np.ptp(m_loss) == 0.0  # no loss acts before its onset
    # the centre of every sweep is one run: the mass sweep's middle equals the loss sweep's
    assert m_mass[1] == m_loss[1]
    printed = capsys.readouterr().out
    assert "| m from its nominal [%] | -10 to 10 |" in printed
    assert (out / "sweep_attitude.png").stat().st_size > 10_000
    assert (out / "sweep.md").read_text().splitlines()[0].startswith("# One-at-a-time")


def _attribution(pawn_m: float, pawn_loss: float, dummy: float) -> Attribution:
    nan = float("nan")
    return Attribution("attitude", 1000, 5, dummy, (
        Driver("s.m", "m", pawn_m, nan, nan, (nan, nan)),
        Driver("fault.loss", "loss", pawn_loss, nan, nan, (nan, nan)),
    ))  # fmt: skip


def test_the_table_says_whether_the_sweep_agrees_with_pawn():
    man = {"name": "c", "duration": 5.0, "requirements": ["attitude"],
           "campaign": {"dispersions": {"uncertainty": {"scale": 1.0}}}}  # fmt: skip
    sweeps = [Sweep("s.m", np.array([-1.0, 0.0, 1.0]), {"attitude": np.array([0.1, 0.3, 0.4])}),
              Sweep("fault.loss", np.array([0.0, 0.1, 0.2]),
                    {"attitude": np.array([0.3, 0.3, 0.31])})]  # fmt: skip
    agree = "\n".join(sweep_lines(man, sweeps, {"attitude": _attribution(0.4, 0.05, 0.08)}))
    assert "| 0.400 | yes |" in agree and "| 0.050 | no |" in agree
    assert "The leading 2 agree (s.m, fault.loss); Spearman's rank correlation over all 2 " \
        "inputs 1.00." in agree
    disagree = "\n".join(sweep_lines(man, sweeps, {"attitude": _attribution(0.05, 0.4, 0.08)}))
    assert "Largest by PAWN: fault.loss, s.m; largest spreads of the sweep: s.m, fault.loss. " \
        "The leading 0 agree (none); Spearman's rank correlation over all 2 inputs -1.00." \
        in disagree
