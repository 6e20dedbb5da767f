"""`fahv clearance` end to end on Case 1's campaign (short runs, a small budget), its
folder, the rerun of its worst case, and the input it refuses."""

import json

import pytest

from fahv.cli import main
from fahv.runs.workspace import ROOT

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
