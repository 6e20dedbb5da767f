"""Campaigns on a LocalCluster: nothing lost, nothing twice, the same table every way.

The campaigns fly scenario case1_paper on its shipped design (cm_paper, loaded and
verified as `fahv campaign` finds it, never designed here). One reference campaign serves
every test that reads, reports or re-runs a campaign; the campaigns that resume a folder,
run forced failures or reach an existing cluster share one LocalCluster of one worker
(`cluster`, warm after its first campaign), so that only the tests about the engine's own
cluster (one and two workers, a killed worker, Ctrl-C of the command) start one of their
own.
"""

import functools
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import binom

from fahv.campaign import engine, store
from fahv.campaign.engine import run_batch, run_campaign
from fahv.campaign.report import failure_bound, make_report, verdicts
from fahv.campaign.rerun import rerun
from fahv.campaign.spec import load_campaign
from fahv.runs.bag import read_run, run_result_of
from fahv.runs.metrics import settling_after

VOLATILE = ("wall_s", "session")  # the only columns that may differ between sessions
#: The campaigns' scenario: Case 1 of the paper on its shipped design.
SCENARIO = Path(__file__).resolve().parents[2] / "offline_design" / "scenarios" / "case1_paper.yaml"


def _table(out):
    rows = store.read_rows(out)
    return [{k: v for k, v in r.items() if k not in VOLATILE} for r in rows]


def _same_tables(a, b):
    assert [(r["variant"], r["index"]) for r in a] == [(r["variant"], r["index"]) for r in b]
    for ra, rb in zip(a, b, strict=True):
        assert ra.keys() == rb.keys()
        for k in ra:
            x, y = ra[k], rb[k]
            same = x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y))
            assert same, (ra["index"], k, x, y)


def _each_index_once(out, runs):
    rows = store.read_rows(out)
    assert sorted(r["index"] for r in rows) == list(range(runs))


@pytest.fixture(scope="module")
def write_campaign(request, tmp_path_factory):
    """``write_campaign(name, **changes)`` as in tests/campaign/conftest.py (its `BASE`
    campaign with the changes), around `SCENARIO` instead of the quick design: the engine
    runs any stored design alike, and the shipped one is loaded, not designed."""
    conftest = request.config.pluginmanager.get_plugin(str(Path(__file__).with_name(
        "conftest.py")))  # fmt: skip
    folder = tmp_path_factory.mktemp("mc")
    return functools.partial(conftest.campaign_file, folder, scenario=str(SCENARIO))


@pytest.fixture(scope="module")
def cluster():
    """An existing Dask cluster (a LocalCluster of one single-threaded worker) that the
    campaigns reach by its scheduler's address; it outlives every campaign run on it."""
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, dashboard_address=None) as c:
        yield c


@pytest.fixture(scope="module")
def reference(write_campaign, tmp_path_factory):
    """The uncertainty-, fault-, command- and start-dispersed campaign, uninterrupted."""
    c = load_campaign(write_campaign("ref"))
    out = tmp_path_factory.mktemp("ref") / "out"
    res = run_campaign(c, out, workers=2, progress=False, log=lambda *_: None)
    assert (res.new, res.failed, res.missing, res.errors) == (12, 0, 0, [])
    return c, out


def test_reference_campaign_has_every_run_once(reference):
    c, out = reference
    _each_index_once(out, c["runs"])
    rows = store.read_rows(out)
    assert {r["status"] for r in rows} == {"ok"}
    assert {r["fault.kind"] for r in rows} == {"loss_of_effectiveness", "bias", "dropout"}
    # 6 batches of 2, each a Parquet file; trajectories of every run
    assert len(list((out / "results").glob("part-*.parquet"))) == 6
    trajs = {t["index"]: t for t in store.read_rows(out, store.TRAJECTORIES)}
    assert sorted(trajs) == list(range(12))
    for r in rows:  # the metrics are those of the stored histories (decimated to 0.5 s)
        tr = trajs[r["index"]]
        assert len(tr["t"]) == 12 and tr["t"][1] == pytest.approx(0.5)
        sampled = max(abs(a) for a in tr["alpha_err_deg"])
        assert 0.0 < sampled <= r["alpha_err_max_deg"] * (1 + 1e-6)


def test_one_and_two_workers_give_identical_tables(reference, tmp_path):
    c, out = reference
    one = tmp_path / "one"
    run_campaign(c, one, workers=1, progress=False, log=lambda *_: None)
    _same_tables(_table(out), _table(one))


def test_killing_a_worker_mid_campaign_loses_nothing(reference, tmp_path):
    c, out = reference
    killed = []

    def kill_one(client, written):
        if killed:
            return
        pids = client.run(os.getpid)
        busy = [w for w, keys in client.processing().items() if keys and w in pids]
        victim = (busy or sorted(pids))[0]
        os.kill(pids[victim], signal.SIGKILL)
        killed.append((victim, bool(busy), written))

    dst = tmp_path / "killed"
    res = run_campaign(c, dst, workers=2, progress=False, on_batch=kill_one, log=lambda *_: None)
    assert killed and killed[0][1] and killed[0][2] < 12  # a busy worker died before the end
    assert res.missing == 0 and res.errors == []
    _each_index_once(dst, c["runs"])
    _same_tables(_table(out), _table(dst))


def test_ctrl_c_then_resume_completes_exactly_the_missing_runs(reference, cluster, tmp_path):
    """Ctrl-C of `fahv campaign` (its own LocalCluster) keeps the finished batches; a
    resume (on another cluster) runs exactly the missing runs, the table the reference's."""
    c, out = reference
    dst = tmp_path / "interrupted"
    fahv = Path(sys.executable).parent / "fahv"
    cmd = [str(fahv), "campaign", str(c.path), "--out", str(dst), "--workers", "1", "--quiet",
           "--no-report"]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not list((dst / "results").glob("part-*.parquet")) and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "--resume" in err
    before = len(store.read_rows(dst))
    assert 0 < before < 12  # interrupted for real: some runs done, some missing
    res = run_campaign(c, dst, scheduler=cluster.scheduler_address, resume=True,
                       progress=False, log=lambda *_: None)  # fmt: skip
    assert (res.before, res.new, res.missing) == (before, 12 - before, 0)
    _each_index_once(dst, c["runs"])
    _same_tables(_table(out), _table(dst))
    assert {r["session"] for r in store.read_rows(dst)} == {1, 2}
    # a second resume has nothing to do; a plain re-run refuses the folder
    assert run_campaign(c, dst, resume=True, progress=False).new == 0
    with pytest.raises(Exception, match="--resume"):
        run_campaign(c, dst, progress=False)


def test_forced_failures_are_recorded_while_the_others_complete(write_campaign, cluster,
                                                                 tmp_path):  # fmt: skip
    """Failed runs are rows with their reason and metrics; the others complete; the report
    counts them and bounds the failure probability."""
    # a stuck elevator from t = 0 loses the unstable short period: the vehicle leaves
    # the envelope; the runs without fault complete
    fault = {"kinds": ["none", "stuck"], "onset": [0.0, 0.0]}
    path = write_campaign("fail", runs=6, batch_size=6, duration=10.0, fault=fault, command={},
                          initial={})  # fmt: skip
    c = load_campaign(path)
    res = run_campaign(c, tmp_path / "f", scheduler=cluster.scheduler_address, progress=False,
                       log=lambda *_: None)  # fmt: skip
    rows = store.read_rows(tmp_path / "f")
    assert res.failed == sum(r["fault.kind"] == "stuck" for r in rows) > 0
    for r in rows:
        if r["fault.kind"] == "stuck":
            assert r["status"] == "failed" and "left the flight envelope" in r["reason"]
            assert r["alpha_err_max_deg"] > 5.0  # metrics of the failed run are kept
        else:
            assert r["status"] == "ok" and r["reason"] == ""
    rep = make_report(tmp_path / "f", figures=False)
    ok, n, bound = rep.table["tube_mpc"]["completes"]
    assert (ok, n) == (6 - res.failed, 6)
    assert bound == pytest.approx(failure_bound(res.failed, 6, 0.95))


def test_a_non_finite_parameter_fails_its_run_only(reference, monkeypatch):
    from fahv.spec.artefacts import load_design

    c, out = reference
    design = load_design(out / "design")  # the campaign's own
    real = engine.overrides

    def poisoned(values, design, variant, *scale):
        ov = real(values, design, variant, *scale)
        if values["s.m"] == poisoned.target:
            ov["plant"]["params.m"] = math.nan
        return ov

    from fahv.campaign.draws import draw

    poisoned.target = draw(c.data, design.case, 1)["s.m"]
    monkeypatch.setattr(engine, "overrides", poisoned)
    batch = run_batch(design, c.data, "tube_mpc", [0, 1, 2], 1.0)
    status = [(r["index"], r["status"]) for r in batch["rows"]]
    assert status == [(0, "ok"), (1, "failed"), (2, "ok")]
    reason = batch["rows"][1]["reason"]
    assert reason == "ParameterError: plant: parameter 'params.m' must be finite, got nan"
    assert batch["rows"][1].get("alpha_err_max_deg") is None
    assert len(batch["trajectories"]) == 2


def test_rerun_reproduces_the_metrics_exactly(reference, tmp_path):
    c, out = reference
    r = rerun(out, 7, bags=tmp_path)
    assert r.identical and r.error == ""
    assert r.metrics["alpha_err_max_deg"] == r.recorded["alpha_err_max_deg"]
    run = run_result_of(read_run(r.bag))  # a run folder the run tools read
    assert run.t.size == 300
    assert read_run(r.bag).metadata["run_index"] == "7"


def test_rerun_metadata_and_topics_agree_on_the_run_s_own_fault(reference, tmp_path):
    """The metadata once said the case file's fault (rho_f 0.9 at 100 s) while the
    fault topic showed the run's own; now both are the run's, with its dispersed values."""
    c, out = reference
    index = 2
    r = rerun(out, index, bags=tmp_path)
    assert r.identical
    assert r.bag.name.startswith(f"ref_{index}_tube_mpc_rerun_")
    rec = read_run(r.bag)
    md, fs = rec.metadata, rec.records["/hsv/fault_status"][-1]
    row = next(x for x in store.read_rows(out) if x["index"] == index)
    assert md["fault_kind"] == fs["kind"] == row["fault.kind"]
    assert float(md["fault_t_onset"]) == fs["t_onset"] == row["fault.t_onset"]
    assert md["fault_t_onset"] != "100.0"  # not the case file's
    if fs["kind"] == "loss_of_effectiveness":
        assert float(md["fault_rho_f"]) == fs["rho_f"] == row["fault.rho_f"]
    if fs["kind"] == "bias":
        assert float(md["fault_bias_deg"]) == pytest.approx(np.degrees(fs["bias"]), rel=1e-12)
    # the campaign run's identity and every dispersed value travel with the file
    assert md["campaign"] == "ref" and md["run_index"] == str(index)
    assert md["campaign_seed"] == str(c["seed"])
    for col in ("fault.t_onset", "s.m", "command.h_c", "initial.V0"):
        assert md[f"dispersed.{col}"] == str(row[col]), col
    # the run's coverage verdict, with its own fault and command, in the row and the file
    assert md["coverage"] == row["coverage"] and row["coverage"].startswith(
        ("certified", "not certified: ")
    )


@pytest.fixture(scope="module")
def report_page(reference):
    """`fahv report DIR` of the reference campaign, once: (the `make_report` result its page
    was made from (figures drawn), the page, what the command printed). The figures are
    drawn once for the tests of the report's numbers and of its page."""
    import contextlib
    import io

    from fahv.campaign import report_page as page
    from fahv.cli import main

    _, out = reference
    made = []

    def kept(*args, **kwargs):  # the page's own call of make_report, its result kept
        made.append(make_report(*args, **kwargs))
        return made[-1]

    printed = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(printed):
        mp.setattr(page, "make_report", kept)
        assert main(["report", str(out)]) == 0
    [rep] = made
    return rep, out / "report" / "report.html", printed.getvalue()


def test_report_numbers(reference, report_page):
    """The report's pass rates, bounds, figures and certified split (`make_report` with
    figures, as `fahv report` calls it)."""
    c, out = reference
    rep = report_page[0]
    rows = store.read_rows(out)
    req = c["requirements"]
    att = sum(verdicts(r, req)["attitude"] for r in rows)
    assert rep.table["tube_mpc"]["attitude"][:2] == (att, 12)
    assert att == sum(max(r["alpha_err_max_deg"], r["theta_err_max_deg"]) <= 0.5 for r in rows)
    assert rep.table["tube_mpc"]["completes"] == (12, 12, pytest.approx(1 - 0.05 ** (1 / 12)))
    names = {p.name for p in rep.figures}
    assert {"hist_alpha_err_max_deg.png", "scatter_alpha_err_max_deg.png",
            "worst_trajectories.png"} <= names  # fmt: skip
    assert all(p.stat().st_size > 5000 for p in rep.figures)
    assert "| attitude error within +/- 0.5 deg |" in rep.text
    # the certified and the not certified draws apart: every run in one group
    groups = rep.by_coverage
    assert set(groups) == {"certified", "not certified"}
    assert sum(groups[g]["tube_mpc"]["completes"][1] for g in groups) == 12
    outside = [r for r in rows if r["fault.kind"] == "dropout" and r["fault.t_onset"] < 6.0]
    assert outside and all("fault kind dropout outside" in r["coverage"] for r in outside)
    n_not = sum(r["coverage"] != "certified" for r in rows)
    assert groups["not certified"]["tube_mpc"]["completes"][1] == n_not
    assert f"### not certified: {n_not} of 12 draws" in rep.text


def test_report_writes_its_head_as_evidence(reference, tmp_path, capsys):
    """`--write FILE`: the report's head (title, dataset, wall times, pass rates), which
    the report itself begins with, and no worst runs or figures."""
    from fahv.cli import main

    _, out = reference
    evidence = tmp_path / "evidence" / "overview.md"
    assert main(["campaign", "report", str(out), "--no-figures", "--write",
                 str(evidence)]) == 0  # fmt: skip
    assert f"overview written to {evidence}" in capsys.readouterr().out
    head = evidence.read_text()
    assert (out / "report" / "report.md").read_text().startswith(head)
    assert head.startswith("# Campaign ") and "| every requirement at once | " in head
    assert "wall time" in head and "## Worst" not in head and "![" not in head


def test_report_command_prints_a_summary_and_the_path(reference, capsys):
    """The command prints a short summary and the report file, not the whole report."""
    from fahv.cli import main

    c, out = reference
    assert main(["campaign", "report", str(out), "--no-figures"]) == 0
    text = capsys.readouterr().out
    assert f"report: {out / 'report' / 'report.md'}" in text
    # a header, a line per requirement, the certified split, the path: not the report
    from fahv.campaign.report import REQUIREMENTS

    assert "## Worst" not in text and len(text.splitlines()) <= len(REQUIREMENTS) + 4
    # the paper's design (W not closed over its domain) certifies none of the draws
    assert "\n  all, certified | not certified draws: tube_mpc 0/0 | " in text
    rep = (out / "report" / "report.md").read_text()
    assert "## Worst 3 runs per metric" in rep
    # every reason a draw is not certified with its numbers, no template left ('#')
    reasons = rep.split("Why draws are not certified")[1].split("\n## ")[0]
    listed = [line for line in reasons.splitlines() if line.startswith("- ")]
    assert listed and all("#" not in line for line in listed), reasons
    assert any(re.search(r"onset loss [\d.]+ to [\d.]+ % above", line) for line in listed)
    att = sum(verdicts(r, c["requirements"])["attitude"] for r in store.read_rows(out))
    assert re.search(rf"attitude\s+{att}/12 ", text), text
    # the worst-run tables print what their label says: |h - h_c|, |V - V_c| (absolute)
    rows = {r["index"]: r for r in store.read_rows(out)}
    for label, key in (("|h - h_c| at the end [ft]", "h_err_final_ft"),
                       ("|V - V_c| at the end [ft/s]", "V_err_final_fps")):  # fmt: skip
        block = rep.split(f"{label}, tube_mpc:")[1].split("\n\n")[1]
        for line in block.splitlines()[2:]:
            idx, value = (x.strip() for x in line.split("|")[1:3])
            assert float(value) == pytest.approx(abs(rows[int(idx)][key]), rel=1e-3)
    assert any(rows[i]["h_err_final_ft"] < 0 for i in rows)  # signed in the dataset


@pytest.mark.parametrize(("k", "n"), [(0, 59), (0, 1000), (3, 100), (10, 20)])
def test_failure_bound_is_clopper_pearson(k, n):
    p = failure_bound(k, n, 0.95)
    assert binom.cdf(k, n, p) == pytest.approx(0.05, rel=1e-6)  # P(<= k failures | p) = 1 - C
    if k == 0:
        assert p == pytest.approx(1 - 0.05 ** (1 / n), rel=1e-12)
    assert failure_bound(0, 59, 0.95) == pytest.approx(0.0495, abs=1e-4)  # the "59 runs" rule
    assert np.isnan(failure_bound(0, 0, 0.95)) and failure_bound(5, 5, 0.95) == 1.0


def test_existing_cluster_by_scheduler_address(reference, cluster, tmp_path):
    """A campaign on a cluster started elsewhere: the same table; the cluster lives on."""
    c, out = reference
    res = run_campaign(c, tmp_path / "ext", scheduler=cluster.scheduler_address,
                       progress=False, log=lambda *_: None)  # fmt: skip
    assert res.missing == 0
    assert len(cluster.scheduler_info["workers"]) == 1  # the cluster outlives the call
    assert store.read_manifest(tmp_path / "ext")["sessions"][0]["engine"] == (
        cluster.scheduler_address
    )
    _same_tables(_table(out), _table(tmp_path / "ext"))


def test_lost_scheduler_keeps_finished_runs_and_resume_completes(reference, cluster, tmp_path):
    """A scheduler lost mid-campaign: the finished batches are kept, the lost ones named;
    a resume (on another cluster) completes the table."""
    import socket

    c, out = reference
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    addr = f"tcp://127.0.0.1:{port}"
    dask = str(Path(sys.executable).parent / "dask")
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    sched = subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                              "--no-dashboard"], **quiet)  # fmt: skip
    worker = subprocess.Popen([dask, "worker", addr, "--nthreads", "1", "--no-dashboard",
                               "--no-nanny"], **quiet)  # fmt: skip
    try:
        lost = []

        def kill_scheduler(client, written):
            if not lost:
                sched.kill()
                lost.append(written)

        dst = tmp_path / "lost"
        res = run_campaign(c, dst, scheduler=addr, progress=False, on_batch=kill_scheduler,
                           log=lambda *_: None)  # fmt: skip
    finally:
        sched.kill()
        worker.kill()
        sched.wait(timeout=30)
        worker.wait(timeout=30)
    assert lost and res.missing > 0 and res.errors
    assert any("scheduler-connection-lost" in e for e in res.errors)
    kept = len(store.read_rows(dst))
    assert kept == res.new >= 2
    res = run_campaign(c, dst, scheduler=cluster.scheduler_address, resume=True,
                       progress=False, log=lambda *_: None)  # fmt: skip
    assert res.before == kept and res.missing == 0
    _each_index_once(dst, c["runs"])
    _same_tables(_table(out), _table(dst))


@pytest.mark.parametrize(
    ("h", "V", "expected"), [(5.0, math.nan, math.nan), (math.nan, 5.0, math.nan), (3.0, 7.0, 6.0)]
)
def test_settling_after_command(h, V, expected):
    got = settling_after(h, V, 1.0)
    assert got == expected or (math.isnan(got) and math.isnan(expected))


def test_settling_needs_both_h_and_V(reference):
    c, out = reference
    for r in store.read_rows(out):
        ts = (r["settling_time_h_s"], r["settling_time_V_s"])
        if any(math.isnan(x) for x in ts):
            assert math.isnan(r["settling_after_command_s"])
        else:
            assert r["settling_after_command_s"] == max(ts) - r["t_command_end_s"]


def test_sessions_are_recorded_in_the_manifest(reference):
    c, out = reference
    sessions = store.read_manifest(out)["sessions"]
    assert [(s["session"], s["new"], s["failed"]) for s in sessions] == [(1, 12, 0)]
    assert sessions[0]["engine"] == "LocalCluster(2)" and sessions[0]["wall_s"] > 0
    assert "Part 1 (LocalCluster(2)): 12 runs (0 failed) in" in make_report(out, False).text


def test_the_report_page_of_a_campaign_has_its_bounds_and_figures(reference, report_page,
                                                                   rendered_body):  # fmt: skip
    """`fahv report DIR`: the pass rates with their bounds, the worst runs and every figure
    of the report in one page, the figures embedded; Chromium loads every image."""
    _, out = reference
    rep, page, printed = report_page
    assert page == out / "report" / "report.html"
    assert printed.strip() == f"report: {page}"
    text = page.read_text()
    assert "p_fail &lt;" in text  # each pass rate's bound
    assert "<td>final |h - h_c| &lt;= 10 ft</td>" in text  # a cell of its own, not split
    assert "Worst 3 runs per metric" in text and "<table>" in text
    n = text.count('src="data:image/png;base64,')
    assert n == len(rep.figures) >= 3 and 'src="' + "hist" not in text  # every figure inside
    body = rendered_body(page)
    assert body["data-images"] == body["data-images-loaded"] == str(n)
