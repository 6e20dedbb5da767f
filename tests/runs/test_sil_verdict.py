"""A run of the node graph that ends with a verdict: the node that finds it and its peers
stop with it, the recorder finishes the file with it, `fahv sil` names it and exits 3;
the verdict, step and time are the in-process simulator's, with the loop nodes in a process
each and composed in one."""

import pytest
import yaml

from fahv.certificate.verified import load_or_design
from fahv.cli import main
from fahv.cli.run import EXIT_VERDICT
from fahv.loop.simulate import simulate
from fahv.runs.bag import read_run, run_result_of
from fahv.sil.workspace import ROOT
from fahv.verdict import RunEnded, Verdict

pytestmark = pytest.mark.ros  # runs the built node graph


@pytest.mark.parametrize("compose", [False, True], ids=["process_per_node", "composed"])
def test_a_stuck_elevator_ends_the_graph_with_the_simulators_verdict(tmp_path, capsys, compose):
    spec = yaml.safe_load((ROOT / "offline_design/scenarios/case1.yaml").read_text())
    spec["fault"] = {"kind": "stuck", "t_onset": 1.0}
    case = tmp_path / "case1_stuck.yaml"
    case.write_text(yaml.safe_dump(spec, sort_keys=False))
    out = tmp_path / "bags"
    rc = main(["sil", str(case), "--duration", "8", "--out", str(out), "--quiet"]
              + (["--compose"] if compose else []))  # fmt: skip
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert rc == EXIT_VERDICT
    (bag,) = out.iterdir()
    rec = read_run(bag)
    got = Verdict.from_metadata(rec.metadata)
    # the in-process run of the same scenario ends with the same verdict at the same step
    _, design, _ = load_or_design(case, log=lambda *_: None)
    with pytest.raises(RunEnded) as ended:
        simulate(design, None, 8.0)
    assert got == ended.value.verdict
    assert (got.name, got.node, got.step) == ("nominal_out_of_domain", "nominal_trajectory", 275)
    assert rec.metadata["status"] == "ended: nominal_out_of_domain"
    assert int(rec.metadata["steps_recorded"]) == 275
    assert f"run {bag.name} ended: nominal_out_of_domain at t = 5.50 s (step 275, " in err
    run = run_result_of(rec)
    assert (run.x == ended.value.partial.x).all()
    assert rec.metadata["graph_processes"] == ("composed" if compose else "per_node")
    if compose:  # one process ran the loop nodes: one log with each one's end
        assert sorted(p.name for p in (bag / "logs").iterdir()) == ["loop.log", "recorder.log"]
        text = (bag / "logs" / "loop.log").read_text()
        assert "[loop] closed with exit status 6" in text
        assert "[nominal_trajectory] run ended: nominal_out_of_domain" in text
    assert main(["inspect", str(bag)]) == 0
    assert "verdict       nominal_out_of_domain at t = 5.50 s" in capsys.readouterr().out
