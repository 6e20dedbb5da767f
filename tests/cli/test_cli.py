"""The fahv command line (modelling subcommands)."""

import json

from fahv.cli import main
from fahv.runs.writer import RunWriter


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


def test_simulate_runs_the_default_variant_unless_told(raw):
    """`fahv simulate CASE` runs the case's first variant; `--variant all` every one."""
    import pytest

    from fahv.cli.run import selected_variants
    from fahv.errors import FahvError
    from fahv.spec.files import spec_file

    case = spec_file(raw, "case1.yaml")
    assert selected_variants(case, None) == ["tube_mpc"]
    assert selected_variants(case, ["all"]) == list(raw["variants"])
    assert selected_variants(case, ["rmpc", "tube_mpc", "rmpc"]) == ["rmpc", "tube_mpc"]
    with pytest.raises(FahvError, match="not in the case's variants"):
        selected_variants(case, ["tube_mpc_online"])


def test_simulate_all_prints_a_progress_line_per_variant(quick_case, tmp_path, capsys):
    case_file, art = quick_case
    args = ["simulate", str(case_file), "--design", str(art), "--no-record",
            "--duration", "0.1", "--variant", "all", "--json"]  # fmt: skip
    assert main(args) == 0
    out = capsys.readouterr()
    table = json.loads(out.out)
    # the test design's variants (without the RMPC baseline, tests/conftest.py)
    assert list(table) == ["tube_mpc", "tube_mpc_no_notch", "tube_mpc_notch2",
                           "tube_mpc_paper"]  # fmt: skip
    for i, v in enumerate(table, 1):
        assert f"[{i}/4] case1_paper {v}: done in" in out.err


def test_a_stop_at_the_end_of_a_steps_last_write_reports_the_files_count(
    design, tmp_path, monkeypatch
):
    """A stop deferred to the end of a write (fahv.interrupt) is raised after the file
    counted the step but before the progress bar did: the message's step count is the
    finalised file's (the race CI once hit: file 3944, message 3943)."""
    import pytest

    from fahv.cli import run as run_cli
    from fahv.errors import RunInterrupted
    from fahv.runs.bag import read_run

    real = RunWriter.write_raw
    last = run_cli.StepProgress.LAST_TOPIC

    def write_raw(self, topic, k, data):
        real(self, topic, k, data)
        if topic == last and k == 6:  # step 6 is in the file, then the stop arrives
            raise KeyboardInterrupt

    monkeypatch.setattr(RunWriter, "write_raw", write_raw)
    with pytest.raises(RunInterrupted) as info:
        run_cli._simulate_recorded(design, "tube_mpc", 1.0, tmp_path)
    assert info.value.step == 7
    rec = read_run(info.value.run)
    assert rec.metadata["status"] == "interrupted"
    assert int(rec.metadata["steps_recorded"]) == 7
