"""The fahv command line (modelling subcommands)."""

import json

from fahv.cli import main


def test_trim_json(capsys):
    assert main(["trim", "--h", "85000", "--V", "7702.08", "--json"]) == 0
    row = json.loads(capsys.readouterr().out)[0]
    assert abs(row["alpha_deg"] - 1.644) < 0.01 and abs(row["Phi"] - 0.2681) < 0.002


def test_trim_outside_envelope_exit_2(capsys):
    assert main(["trim", "--h", "90000", "--V", "7900"]) == 2
    assert "outside the flight envelope" in capsys.readouterr().err


def test_vehicle_option_bad_file(tmp_path, capsys):
    assert main(["trim", "--vehicle", str(tmp_path / "missing.yaml")]) == 2
    assert "vehicle file not found" in capsys.readouterr().err


def test_sigterm_on_simulate_finalises_the_run_and_exits_130(quick_case, tmp_path):
    """SIGTERM (then a second signal) to `fahv simulate`: exit 130, the message, no
    traceback, a readable run with status interrupted and as many steps as it says."""
    import os
    import re
    import signal
    import subprocess
    import time

    from fahv.runs.bag import read_run
    from fahv.runs.workspace import ROOT

    case_file, art = quick_case
    out = tmp_path / "bags"
    p = subprocess.Popen(
        [str(ROOT / ".venv" / "bin" / "fahv"), "simulate", str(case_file), "--design", str(art),
         "--out", str(out)],
        start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    t0 = time.monotonic()
    while not list(out.glob("*/run.json")) and time.monotonic() - t0 < 60:
        time.sleep(0.1)
    time.sleep(1.0)
    os.killpg(p.pid, signal.SIGTERM)
    time.sleep(0.1)
    os.killpg(p.pid, signal.SIGINT)
    text, _ = p.communicate(timeout=60)
    assert p.returncode == 130, text
    assert "Traceback" not in text
    m = re.search(r"fahv simulate: interrupted at step (\d+) of 15000; run written to (\S+)", text)
    assert m, text
    rec = read_run(m.group(2))
    assert rec.metadata["status"] == "interrupted"
    assert not rec.truncated
    assert int(rec.metadata["steps_recorded"]) == int(m.group(1))
    assert 0 < int(m.group(1)) < 15000
