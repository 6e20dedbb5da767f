"""`fahv clearance` end to end on Case 1's campaign (short runs, a small budget), its
folder, the rerun of its worst case, and the input it refuses."""

import json

import pytest

from fahv.cli import main
from fahv.sil.workspace import ROOT

CAMPAIGN = str(ROOT / "offline_design/campaigns/case1.yaml")


@pytest.fixture(scope="module")
def cleared(tmp_path_factory):
    """A clearance of the attitude, 20 simulations of 5 s (two generations of CMA-ES) and
    a Monte Carlo of the campaign's first 20 draws, on one worker."""
    out = tmp_path_factory.mktemp("clearance") / "c"
    code = main(["clearance", CAMPAIGN, "--requirement", "attitude", "--budget", "20",
                 "--duration", "5", "--workers", "1", "--monte-carlo", "--out", str(out)])
    assert code == 0
    return out, json.loads((out / "campaign.json").read_text())


def test_the_folder_holds_every_run_the_worst_cases_and_the_figure(cleared, capsys):
    out, man = cleared
    (entry,) = man["requirements"]
    search, mc = entry["search"], entry["monte_carlo"]
    assert entry["requirement"] == "attitude" and entry["unit"] == "deg"
    assert search["simulations"] == 20 and mc["simulations"] == 20
    assert 1000 <= search["index"] < 1020 and 0 <= mc["index"] < 20  # after the draws'
    # 5 s runs of Case 1: attitude errors of 0.1-0.45 deg, margins inside (0, 0.5)
    assert 0.0 < search["margin"] < 0.5 and 0.0 < mc["margin"] < 0.5
    assert set(search["values"]) >= {"s.m", "fault.t_onset", "fault.loss", "fault.rho_f"}
    assert (out / "convergence_attitude.png").stat().st_size > 10_000
    table = (out / "clearance.md").read_text()
    assert f"| attitude | {search['margin']:.4g} deg | {search['index']} | 20 |" in table
    assert man["kind"] == "clearance" and man["optimizer"] == "cma"
    assert len(man["variables"]) == 12  # ten parameters, the onset, the loss


def test_the_worst_case_reruns_to_the_same_metrics(cleared, capsys):
    """`fahv campaign rerun DIR INDEX` of the worst case flies its values again: the same
    metrics as its row, bit for bit."""
    out, man = cleared
    index = man["requirements"][0]["search"]["index"]
    code = main(["campaign", "rerun", str(out), str(index), "--out", str(out / "bags")])
    assert code == 0
    assert "metrics identical to the campaign's row" in capsys.readouterr().out


def test_bad_requests_are_refused_naming_them(tmp_path, capsys):
    assert main(["clearance", CAMPAIGN, "--budget", "5", "--out", str(tmp_path / "a")]) == 2
    assert "--budget 5: below one generation of 10 simulations" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["clearance", CAMPAIGN, "--requirement", "completes"])
    assert "invalid choice: 'completes'" in capsys.readouterr().err


def test_the_certificate_check_searches_only_what_the_design_certifies(tmp_path, capsys):
    """`--certificate` on Case 1: the losses searched stop at cm_certified's certified onset
    loss (8.07 %, where the campaign ranges to 24 %), every margin is a certified run's,
    and a tube or attitude held everywhere reads as such, exit status 0."""
    out = tmp_path / "cert"
    code = main(["clearance", CAMPAIGN, "--certificate", "--budget", "10", "--duration", "5",
                 "--workers", "1", "--out", str(out)])  # fmt: skip
    printed = capsys.readouterr().out
    assert code == 0
    man = json.loads((out / "campaign.json").read_text())
    loss = next(v for v in man["variables"] if v["name"] == "fault.loss")
    assert loss["hi"] == pytest.approx(0.0807, abs=5e-5) and man["certificate"] is True
    for e in man["requirements"]:
        assert e["certificate"] == {"certified_runs": 10, "failures": []}
    assert "certificate: tube held in all 10 certified runs searched" in printed


def test_a_certificate_failure_is_named_with_its_run():
    from fahv.clearance.report import summary_lines

    worst = {"margin": -0.02, "simulations": 40, "index": 1033}
    man = {"name": "case1", "budget": 40, "design_hash": "x", "requirements": [
        {"requirement": "tube", "unit": "-", "search": worst, "monte_carlo": None,
         "certificate": {"certified_runs": 40, "failures": [1033, 1038]}}]}  # fmt: skip
    lines = summary_lines(man)
    assert lines[2].startswith("tube            -0.02 - (40 runs)")
    assert lines[-1] == ("CERTIFICATE FAILURE: tube missed in 2 certified run(s), the worst "
                         "run 1033 (fahv campaign rerun DIR INDEX flies it)")  # fmt: skip


def test_the_worst_case_scenario_file_flies_the_same_run(cleared):
    """`worst_attitude.yaml` extends the campaign's scenario with the run's values: flown by
    the simulator from the file alone, every metric equals the searched run's row."""
    import math

    from fahv.campaign import store
    from fahv.certificate.verified import load_or_design
    from fahv.loop.simulate import simulate
    from fahv.model.vehicle import load_vehicle
    from fahv.runs.metrics import metrics

    out, man = cleared
    entry = man["requirements"][0]["search"]
    assert entry["scenario"] == "worst_attitude.yaml"
    _, design, _ = load_or_design(str(out / entry["scenario"]), log=lambda *_: None,
                                  allow_uncertified=True)  # fmt: skip
    assert design.case["uncertainty"]["s"][0] == entry["values"]["s.m"]
    m = metrics(simulate(design, "tube_mpc"), load_vehicle().limits)
    row = next(r for r in store.read_rows(out) if r["index"] == entry["index"])
    same = [k for k in m if k in row and (m[k] == row[k] or (
        isinstance(m[k], float) and math.isnan(m[k]) and math.isnan(row[k])))]
    assert len(same) == len(m) >= 40


def test_the_report_beside_a_finished_campaign(cleared, tmp_path, capsys):
    """`fahv clearance report DIR --against CAMPAIGN_DIR` adds the worst margin of a finished
    campaign of the same file (here its first 6 draws of 5 s): the smallest of its runs'
    margins, in the table, the Markdown and the manifest; another campaign is refused."""
    import numpy as np

    from fahv.campaign import store
    from fahv.campaign.robustness import robustness

    out, _ = cleared
    camp = tmp_path / "camp"
    assert main(["campaign", CAMPAIGN, "--runs", "6", "--duration", "5", "--workers", "1",
                 "--out", str(camp), "--no-report"]) == 0  # fmt: skip
    capsys.readouterr()
    assert main(["clearance", "report", str(out), "--against", str(camp)]) == 0
    printed = capsys.readouterr().out
    rows = store.read_rows(camp)
    worst = min(robustness(r, "attitude") for r in rows)
    man = json.loads((out / "campaign.json").read_text())
    entry = man["requirements"][0]["campaign"]
    assert entry["runs"] == 6 and entry["margin"] == pytest.approx(worst, abs=1e-12)
    assert f"{worst:.4g} deg (6 runs)" in printed
    assert "the campaign's 6 runs" in (out / "clearance.md").read_text()
    assert np.isfinite(entry["margin"])
    assert main(["clearance", "report", str(out), "--against", str(out)]) == 2
    assert "not a campaign of case1" in capsys.readouterr().err


def test_the_report_against_a_campaign_judges_input_rates_by_the_recorded_servo(tmp_path):
    """A clearance records its elevator servo's rate limit; `report --against` judges the
    campaign's input rates by it (before, without it, their margin was NaN)."""
    from fahv.campaign import store
    from fahv.clearance.report import report

    clearance, campaign = tmp_path / "clearance", tmp_path / "campaign"
    clearance.mkdir()
    campaign.mkdir()
    store.write_manifest(clearance, {
        "kind": "clearance", "name": "c", "rate_limit_degps": 100.0, "design_hash": "d",
        "budget": 10, "duration": 5.0,
        "campaign": {"variants": ["tube_mpc"], "requirements": {}},
        "requirements": [{"requirement": "input_rates", "unit": "deg/s",
                          "search": {"margin": 5.0, "simulations": 10, "index": 1000},
                          "monte_carlo": None}]})  # fmt: skip
    store.write_manifest(campaign, {"name": "c"})  # a campaign's manifest has no kind
    store.write_part(campaign, store.RESULTS, "part-0", [
        {"index": i, "variant": "tube_mpc", "status": "ok", "delta_e_rate_max_degps": r,
         "actuators.rate_limit": f} for i, (r, f) in enumerate([(60.0, 1.0), (95.0, 0.9)])])
    man = report(clearance, campaign)
    worst = man["requirements"][0]["campaign"]
    assert worst == {"margin": pytest.approx(100.0 * 0.9 - 95.0), "runs": 2, "index": 1}
