"""Every fault kind on Case 1 through `fahv simulate`: the run completes (exit 0) or ends
with a named verdict (exit 3) at a named step, time and node, in the run file and in
`fahv inspect`; never a traceback. A fault kind of a plugin is held to the same. Each
run's coverage verdict is printed once and stored."""

import importlib
import os
import sys
from pathlib import Path

import pytest
import yaml

from fahv.cli import main
from fahv.cli.run import EXIT_VERDICT
from fahv.control import load_plugins
from fahv.plant.faults import FAULTS
from fahv.runs.bag import read_run
from fahv.sil.workspace import ROOT

HERE = Path(__file__).resolve().parent
CASE1 = ROOT / "offline_design" / "scenarios" / "case1.yaml"
#: Onset and run length of every test run [s]: the runs that end, end by 27 s (step 1350,
#: `EXPECTED`); the others complete their 30 s.
ONSET, DURATION = 20.0, 30.0
#: Parameters of each kind (what the kind takes).
PARAMS = {"loss_of_effectiveness": {"rho_f": 0.9}, "bias": {"bias_deg": 2.0},
          "elevator_travel": {"travel_deg": 12.1}, "hardover": {"side": 1.0}}  # fmt: skip
#: Measured on Case 1 (cm_certified) with the fault at 20 s: verdict, step, node.
EXPECTED = {
    "none": ("completed", 1500, "-"),
    "loss_of_effectiveness": ("completed", 1500, "-"),
    "bias": ("completed", 1500, "-"),
    "stuck": ("nominal_out_of_domain", 1325, "nominal_trajectory"),
    "dropout": ("nominal_out_of_domain", 1350, "nominal_trajectory"),
    "hardover": ("nominal_out_of_domain", 1200, "nominal_trajectory"),
    "elevator_travel": ("nominal_out_of_domain", 1150, "nominal_trajectory"),
}

#: The coverage verdict of each run (design cm_certified, the fault at 20 s).
OUTSIDE = "not certified: fault kind {} outside the design's fault kinds (none, " \
          "loss_of_effectiveness, bias)"  # fmt: skip
COVERAGE = {
    "none": "certified",
    "loss_of_effectiveness": "not certified: onset loss 10 % above the certified 8.07 %",
    "bias": "not certified: onset of a 2 deg bias (the onset lines certify losses only)",
    **{k: OUTSIDE.format(k) for k in ("stuck", "dropout", "hardover", "elevator_travel")},
}
#: The coverage line each run prints: which part of the run the certificate covers.
UP_TO = "certified up to the fault's onset at t = 20 s, not after it: "
PRINTED = {
    **COVERAGE,
    "none": "certified: the certificate covers the whole run",
    "loss_of_effectiveness": UP_TO + COVERAGE["loss_of_effectiveness"].removeprefix(
        "not certified: "),
    "bias": UP_TO + COVERAGE["bias"].removeprefix("not certified: "),
}


@pytest.fixture
def plugin_faults(monkeypatch):
    """The plugin fault kind `elevator_travel` (tests/cli/plugin_faults.py), registered."""
    monkeypatch.syspath_prepend(str(HERE))
    monkeypatch.setenv("FAHV_PLUGINS", "plugin_faults")
    sys.modules.pop("plugin_faults", None)
    assert load_plugins() == ["plugin_faults"]
    yield importlib.import_module("plugin_faults")
    FAULTS.unregister("elevator_travel")


def case1_with(tmp_path: Path, kind: str, actuators: str | None = None) -> Path:
    """A copy of Case 1 with the fault `kind` at `ONSET` (and an actuator model)."""
    spec = yaml.safe_load(CASE1.read_text())
    onset = {} if kind == "none" else {"t_onset": ONSET}  # none has no onset
    spec["fault"] = {"kind": kind, **onset, **PARAMS.get(kind, {})}
    if actuators is not None:
        spec["plant"] = {"actuators": actuators}
    path = tmp_path / f"case1_{kind}.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def simulate_kind(kind: str, tmp_path: Path, capsys, actuators: str | None = None):
    """`fahv simulate` of Case 1 with fault `kind`: (exit status, stderr, the run file).

    With servo `actuators` the scenario is beyond the design (ideal actuators): it runs
    with `--allow-uncertified`.
    """
    out = tmp_path / "bags"
    extra = [] if actuators is None else ["--allow-uncertified"]
    rc = main(["simulate", str(case1_with(tmp_path, kind, actuators)), "--duration",
               str(DURATION), "--out", str(out), *extra])  # fmt: skip
    printed = capsys.readouterr()
    err = printed.err
    assert "Traceback" not in err
    # the coverage verdict, once, before the metrics; the same in the run file
    assert printed.out.count("coverage: ") == 1
    assert f"coverage: {PRINTED[kind]}\ncase case1, design " in printed.out
    (bag,) = out.iterdir()
    rec = read_run(bag)
    assert rec.metadata["coverage"] == COVERAGE[kind]
    return rc, err, rec


def check_verdict(kind: str, rc: int, err: str, rec, capsys) -> None:
    """The exit status, the printed line, the run file and `fahv inspect` agree."""
    md = rec.metadata
    name, step, node = EXPECTED.get(kind, (md["verdict"], int(md["verdict_step"]), None))
    assert md["verdict"] == name and int(md["verdict_step"]) == step
    assert float(md["verdict_t"]) == pytest.approx(step * 0.02, abs=1e-9)
    assert int(md["steps_recorded"]) == step
    if node is not None:
        assert md["verdict_node"] == node
    assert main(["inspect", str(rec.path)]) == 0
    shown = capsys.readouterr().out
    assert f"\ncoverage      {COVERAGE[kind]}\n" in shown
    if name == "completed":
        assert rc == 0 and md["status"] == "complete"
        assert f"verdict       completed at t = {step * 0.02:.2f} s ({step} steps)" in shown
        return
    assert rc == EXIT_VERDICT and md["status"] == f"ended: {name}"
    line = f"{name} at t = {step * 0.02:.2f} s (step {step}, {md['verdict_node']}): "
    assert f"run {rec.path.parent.name} ended: {line}" in err
    assert f"verdict       {line}" in shown
    assert md["verdict_reason"] and md["verdict_reason"] in shown


@pytest.mark.parametrize("kind", FAULTS.names())
def test_every_fault_kind_completes_or_ends_with_its_verdict(kind, tmp_path, capsys):
    rc, err, rec = simulate_kind(kind, tmp_path, capsys)
    check_verdict(kind, rc, err, rec, capsys)
    if kind in ("stuck", "dropout", "hardover"):  # fell through the envelope's floor
        why = rec.metadata["verdict_reason"]
        assert "left the trim map the QP is scheduled on (h in [85000, 86500] ft" in why
        assert "vehicle at h = 84" in why


#: With second-order actuators (the vehicle file's servos): verdict, step, node.
SERVO_EXPECTED = {
    "stuck": ("nominal_out_of_domain", 1325, "nominal_trajectory"),
    "hardover": ("nominal_out_of_domain", 1200, "nominal_trajectory"),
}


@pytest.mark.parametrize("kind", sorted(SERVO_EXPECTED))
def test_actuator_faults_with_servo_dynamics_end_with_their_verdict(
    kind, tmp_path, capsys, monkeypatch
):
    """The stuck servo (held at its position) and the hardover (driven at its rate limit)
    end as named verdicts, the warning names the actuator model beyond the design."""
    monkeypatch.setitem(EXPECTED, kind, SERVO_EXPECTED[kind])
    # the coverage verdict names both: the actuator model first, then the fault kind
    servos = ("the actuator model 'second_order' (plant.actuators) is not in the design "
              "model: the tube and the nominal ellipsoid are certified for ideal actuators")
    both = COVERAGE[kind].replace("not certified: ", f"not certified: {servos}; ")
    monkeypatch.setitem(COVERAGE, kind, both)
    monkeypatch.setitem(PRINTED, kind, both)
    rc, err, rec = simulate_kind(kind, tmp_path, capsys, "second_order")
    assert "the actuator model 'second_order' (plant.actuators) is not in the design" in err
    check_verdict(kind, rc, err, rec, capsys)


def test_a_plugin_fault_kind_ends_with_its_verdict(plugin_faults, tmp_path, capsys):
    # +/-12.1 deg of travel holds neither the climb's deflection (14.4 deg at 20 s) nor
    # the trim (12.3 deg): the vehicle slows, its nominal below the map's 7700 ft/s
    rc, err, rec = simulate_kind("elevator_travel", tmp_path, capsys)
    check_verdict("elevator_travel", rc, err, rec, capsys)
    assert "(h, V) = (85962.1 ft, 7241.2 ft/s)" in rec.metadata["verdict_reason"]
    assert os.environ["FAHV_PLUGINS"] == "plugin_faults"
