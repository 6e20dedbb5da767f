"""Every run judged against its requirements: `fahv simulate` prints the verdict table,
`--check` makes the exit status follow it, `fahv inspect` judges the recorded run alike.

Three runs of Case 1 (60 s, the steps at t = 0, no fault within the run): as shipped (every
requirement met), with a scenario that asks for settling within 20 s (it settles in
33.4 s), and on servos whose rate limits are 5 % of the vehicle file's (the controller
asks the elevator's servo for about 10 deg/s, the limit becomes 5 deg/s). The late
scenario's recorded run (`late_run`) serves both its printed table and `fahv inspect`.
"""

import json
import re
from pathlib import Path

import pytest
import yaml

from fahv.cli import main
from fahv.cli.run import EXIT_REQUIREMENTS
from fahv.sil.workspace import ROOT

CASE1 = ROOT / "offline_design" / "scenarios" / "case1.yaml"
DURATION = "60"


def scenario(tmp_path: Path, name: str, **sections) -> Path:
    """A copy of Case 1 with `sections` set (a `requirements` or `plant` section)."""
    spec = yaml.safe_load(CASE1.read_text())
    spec.update(name=name, **sections)
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def run(path: Path, capsys, *extra: str) -> tuple[int, str]:
    """`fahv simulate` of one scenario for 60 s: (exit status, stdout)."""
    rc = main(["simulate", str(path), "--duration", DURATION, *extra])
    return rc, capsys.readouterr().out


def table(out: str) -> dict[str, list[str]]:
    """The printed verdict table: requirement -> its cells (split at two or more spaces)."""
    lines = out.split("\nrequirements of ", 1)[1].splitlines()[2:]
    cells = [re.split(r"\s{2,}", line.strip()) for line in lines if not line.startswith("verdict")]
    return {c[0]: c[1:] for c in cells}


def record(path: Path, capsys, *extra: str) -> dict:
    """The requirements of `fahv simulate --json`: {requirement: value, limit, margin ...}."""
    rc, out = run(path, capsys, "--no-record", "--json", *extra)
    ((_, m),) = json.loads(out).items()
    return m["requirements"]


def test_a_passing_run_prints_every_requirement_and_exits_0_with_check(tmp_path, capsys):
    rc, out = run(CASE1, capsys, "--no-record", "--check")
    assert rc == 0
    assert "coverage: certified: the certificate covers the whole run" in out
    verdicts = {k: cells[-1] for k, cells in table(out).items()}
    assert verdicts == {"completes": "PASS", "attitude": "PASS", "input_limits": "PASS",
                        "input_rates": "n/a", "tube": "PASS", "settling": "PASS",
                        "settling_fault": "n/a", "final_h": "PASS",
                        "final_V": "PASS"}  # fmt: skip
    assert table(out)["settling_fault"][1] == "no fault after the command"  # onset t = 100 s
    assert "verdict of case1 tube_mpc: PASS" in out
    settling = record(CASE1, capsys)["requirements"]["settling"]
    assert settling["value"] == pytest.approx(33.4, abs=0.1)  # [s] after the command
    assert settling["margin"] == pytest.approx(60.0 - 33.4, abs=0.1)
    assert settling["unit"] == "s"


@pytest.fixture(scope="module")
def late_run(tmp_path_factory):
    """The scenario that asks for settling within 20 s and its run, recorded by `fahv
    simulate` without --check: (scenario file, exit status, stdout, run folder)."""
    import contextlib
    import io

    tmp = tmp_path_factory.mktemp("late")
    late = scenario(tmp, "case1_settle_20s", requirements={"settling_s": 20.0})
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        rc = main(["simulate", str(late), "--duration", DURATION, "--out", str(tmp / "bags")])
    (bag,) = (tmp / "bags").iterdir()
    return late, rc, printed.getvalue(), bag


def test_a_run_that_settles_late_fails_settling_and_check_exits_4(late_run, capsys):
    late, rc, out, _ = late_run
    assert rc == 0  # without --check the exit status is the run's end, not its verdict
    assert table(out)["settling"][-1] == "FAIL"
    assert table(out)["settling"][-2] == "-13.42 s"  # margin: missed by 13.42 s
    assert "verdict of case1_settle_20s tube_mpc: FAIL (settling)" in out
    rc, _ = run(late, capsys, "--no-record", "--check")
    assert rc == EXIT_REQUIREMENTS


def test_a_run_beyond_the_servo_rate_fails_input_rates(tmp_path, capsys):
    slow = scenario(tmp_path, "case1_slow_servos",
                    plant={"actuators": "second_order", "servo_rate_limit_factor": 0.05})
    rc, out = run(slow, capsys, "--no-record", "--check", "--allow-uncertified")
    assert rc == EXIT_REQUIREMENTS
    assert table(out)["input_rates"][-1] == "FAIL"
    assert "verdict of case1_slow_servos tube_mpc: FAIL (input_rates)" in out
    rates = record(slow, capsys, "--allow-uncertified")["requirements"]["input_rates"]
    assert rates["value"] > 0 and rates["limit"] == 0 and rates["unit"] == "steps"


def test_inspect_judges_the_recorded_run_against_its_recorded_limits(late_run, capsys):
    _, _, _, bag = late_run
    assert main(["inspect", str(bag), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert json.loads(s["metadata"]["requirements"])["settling_s"] == 20.0
    req = s["requirements"]
    assert req["verdict"] == "FAIL"
    assert req["requirements"]["settling"]["verdict"] == "FAIL"
    assert req["requirements"]["settling"]["margin"] == pytest.approx(20.0 - 33.4, abs=0.1)
    assert main(["inspect", str(bag)]) == 0
    assert "verdict: FAIL (settling)" in capsys.readouterr().out
