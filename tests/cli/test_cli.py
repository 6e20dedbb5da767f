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


def test_sigterm_on_simulate_finalises_the_run_and_exits_130(quick_case, tmp_path, interrupt_fahv):
    """SIGTERM (then a second signal) to `fahv simulate`: exit 130, the message, no
    traceback, a readable run with status interrupted and as many steps as it says."""
    import signal

    case_file, art = quick_case
    out = tmp_path / "bags"
    steps, _, text = interrupt_fahv(
        ["simulate", case_file, "--design", art, "--out", out], out,
        [signal.SIGTERM, signal.SIGINT], 3.0, 60,  # 3 s: stepping, even under load
    )  # fmt: skip
    assert "fahv simulate: interrupted at step" in text
    assert 0 < steps < 15000
