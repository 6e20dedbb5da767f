"""Details of the `fahv` command: tables, messages, artefact folders, tolerances."""

import math
import re
import subprocess
from importlib import resources

import matplotlib
import numpy as np
import pytest

from fahv.cli import main
from fahv.errors import DesignError
from fahv.loop.simulate import simulate
from fahv.model.vehicle import load_vehicle
from fahv.runs.metrics import metrics
from fahv.runs.tools import METRIC_ROWS, format_metrics
from fahv.sil.workspace import ROOT

matplotlib.use("Agg")

CASE1 = ROOT / "offline_design" / "scenarios" / "case1_paper.yaml"


@pytest.fixture(scope="module")
def design(paper_scenario_design):
    """Case 1 (scenario case1_paper) on its shipped design, as `fahv simulate` runs it
    (loaded and verified, not designed)."""
    return paper_scenario_design


@pytest.fixture(scope="module")
def shipped_case():
    """Case 1's scenario and its shipped design folder, for `fahv sil CASE --design DIR`
    (its first variant: tube_mpc)."""
    return CASE1, ROOT / "offline_design" / "designs" / "cm_paper"


def test_metrics_table_is_aligned_whatever_the_row_names(design):
    lim = load_vehicle().limits
    m = metrics(simulate(design, "tube_mpc", duration=1.0), lim)
    m.update(nominal_qp_solves=3, nominal_qp_fallback=1, nominal_qp_terminal=2)
    text = format_metrics({"tube_mpc": m, "other": m})
    longest = max(len(label) for _, label, _ in METRIC_ROWS)
    assert longest > 36  # the old fixed label width
    assert "nominal steps on the shifted plan (QP rejected)" in text
    # right-aligned cells: every row (header included) ends at the same column
    assert len({len(line) for line in text.splitlines()}) == 1, text
    assert text.splitlines()[0].index("tube_mpc") > longest


def test_after_fault_metrics_of_a_run_that_ends_before_its_fault(design):
    """A 1 s run of Case 1 (fault at 100 s): no "after fault" values, the onset 'none'."""
    lim = load_vehicle().limits
    early = metrics(simulate(design, "tube_mpc", duration=1.0), lim)
    assert math.isnan(early["t_fault_s"])
    text = format_metrics({"tube_mpc": early})
    assert "after fault" not in text
    assert re.search(r"RMS eta_1_dot over the run \(no fault in it\) \[1/s\]\s+\d", text)
    assert re.search(r"fault onset \[s\]\s+none in the run", text)
    # with the fault inside the run: the onset and the "after fault" rows
    ov = {"fault_injector": {"t_onset": 0.5}}
    inside = metrics(simulate(design, "tube_mpc", duration=1.0, overrides=ov), lim)
    assert inside["t_fault_s"] == pytest.approx(0.5, abs=1e-12)
    assert inside["eta_1_dot_rms_after_fault"] != early["eta_1_dot_rms_after_fault"]
    text = format_metrics({"late fault": early, "fault at 0.5 s": inside})
    assert re.search(r"RMS eta_1_dot after fault \[1/s\]\s+\S+\*\s+\S+\d\n", text), text
    assert "* no fault within this run: over the whole run" in text


def test_tube_figure_is_scaled_to_the_levels():
    import matplotlib.pyplot as plt

    from fahv.runs.plots import _tube_axis

    class Run:
        def __init__(self, levels):
            self.tube_level = np.asarray(levels)

    fig, ax = plt.subplots()
    _tube_axis(ax, [("a", Run([0.0, 0.01, 0.033])), ("b", Run([np.nan, 0.02, 0.03]))])
    lo, hi = ax.get_ylim()
    assert (lo, hi) == (0.0, pytest.approx(1.15 * 0.033))  # not a 0-1 axis
    assert any("boundary of Z at level 1" in t.get_text() for t in ax.texts)
    fig, ax = plt.subplots()
    _tube_axis(ax, [("a", Run([0.2, 0.9]))])
    assert ax.get_ylim()[1] >= 1.0 and [ln.get_ydata()[0] for ln in ax.lines] == [1.0]
    plt.close("all")


def test_tube_study_takes_the_case_design_effectiveness(monkeypatch, capsys):
    """`fahv tube` without --rho-f: the rho_f the case designs its tube for (0.76), not 0.9."""
    import fahv.cli.modelling as modelling

    seen = {}

    class Stop(Exception):
        pass

    def fake(veh, tp, Ts, unc, rho_f, *args, **kwargs):
        seen["rho_f"] = rho_f
        raise Stop

    monkeypatch.setattr(modelling, "_tp", lambda *a: None)
    monkeypatch.setattr(modelling, "tube_feasibility", fake)
    with pytest.raises(Stop):
        main(["tube", "--case", str(CASE1)])
    assert seen["rho_f"] == 0.76
    assert "rho_f = 0.76: the elevator effectiveness" in capsys.readouterr().out
    with pytest.raises(Stop):
        main(["tube", "--rho-f", "0.85"])
    assert seen["rho_f"] == 0.85


def test_design_for_another_vehicle_keeps_the_shipped_artefacts(tmp_path, monkeypatch):
    import fahv.cli.design as cli_design
    from fahv.spec.store import design_dir

    text = resources.files("fahv.data").joinpath("vehicle_parker2007.yaml").read_text()
    heavy = tmp_path / "heavy.yaml"
    new, n = re.subn(r"(\n  m:\s+\{value: )300\.0,", r"\g<1>315.0,", text)
    assert n == 1
    heavy.write_text(new)
    dfile = ROOT / "offline_design" / "designs" / "cm_paper.yaml"
    packaged = design_dir(dfile, "cm_paper", None, load_vehicle())
    other = design_dir(dfile, "cm_paper", None, load_vehicle(heavy))
    assert packaged.name == "cm_paper"
    assert other.name == f"cm_paper@heavy-{load_vehicle(heavy).data_hash[:8]}"
    assert other.parent == packaged.parent  # a sibling: saving it cannot replace cm_paper/
    written = []

    def record(spec, vehicle, out, log=print, cold=False):
        written.append(out)
        raise DesignError("stopped by the test")

    monkeypatch.setattr(cli_design, "design_and_store", record)
    assert main(["design", str(dfile), "--vehicle", str(heavy)]) == 2
    assert written == [other]


def test_lmi_certificate_is_reported_against_its_tolerance(design):
    from fahv.errors import DesignError
    from fahv.synthesis.lmi import psd_tolerance, require_psd

    nom = design.summary["nominal"]
    assert nom["lmi34_tol"] > 0 and nom["lmi34_min_eig"] >= -nom["lmi34_tol"]
    M = np.diag([1.0, -4.22e-9])
    assert psd_tolerance(M) == 1e-9
    with pytest.raises(DesignError, match=r"eigenvalue -4\.220e-09 < -1\.00e-09 \(tolerance\)"):
        require_psd(M, "test block")
    assert require_psd(100.0 * np.diag([1.0, -4.22e-9]) / 100.0 + np.diag([100.0, 0]), "x") < 0


@pytest.mark.ros
def test_fahv_sil_says_where_the_run_is_once_and_no_after_fault_metrics(shipped_case, tmp_path):
    """A 1 s SIL run of Case 1 (fault at 100 s): the run folder named once, and the
    flexible RMS labelled over the run, not after a fault that never came."""
    case_file, art = shipped_case
    r = subprocess.run(
        [str(ROOT / ".venv" / "bin" / "fahv"), "sil", str(case_file), "--design", str(art),
         "--duration", "1", "--out", str(tmp_path), "--quiet"],
        cwd=ROOT, capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    both = r.stdout + r.stderr
    assert both.count("run written to") == 1, both
    assert "after fault" not in r.stdout
    assert "RMS eta_1_dot over the run (no fault in it)" in r.stdout


@pytest.mark.ros
def test_fahv_sil_json_writes_only_the_json_to_stdout(shipped_case, tmp_path):
    """`fahv sil --json`: stdout is one JSON document (the metrics per variant), as with
    `fahv simulate --json`; the run's status lines go to stderr."""
    import json

    case_file, art = shipped_case
    r = subprocess.run(
        [str(ROOT / ".venv" / "bin" / "fahv"), "sil", str(case_file), "--design", str(art),
         "--duration", "1", "--out", str(tmp_path), "--quiet", "--json"],
        cwd=ROOT, capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    table = json.loads(r.stdout)
    (metrics,) = table.values()
    assert metrics["settling_time_h_s"] is None or metrics["settling_time_h_s"] >= 0.0
    assert "status complete, 50 of 50 steps" in r.stderr
    assert "logs in" in r.stderr
