"""Every benchmark in benchmarks/ still runs: each at a tiny size (``--smoke``), in seconds.

``--smoke`` runs a benchmark's own code path (its scenario, design and campaign files,
the library calls it times) on a few steps, a short duration, one repeat, a tiny batch
and one Dask worker; the figures it prints mean nothing, but a benchmark whose files
moved or whose library calls changed fails here instead of on the day it is needed.
Each benchmark runs from the repository root in its own process, as documented.
"""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Wall-clock limit of one smoke run [s] (each takes seconds; CI's machine is shared).
TIMEOUT_S = 240
#: A printed figure: a number, maybe with a fraction or an exponent.
NUM = r"\d+(?:\.\d+)?(?:e[+-]?\d+)?"
#: Per benchmark, the figure lines its output must hold (regular expressions, multiline).
FIGURES = {
    "bench_step": [
        rf"^20 steps of \S+ \(design \w+, {NUM} s simulated\) after step 0$",
        rf"^  tube_mpc\s+{NUM} ms/step$",
        rf"^  whole step\s+{NUM} ms/step \(real-time factor {NUM}\)$",
    ],
    "bench_qp": [
        rf"^nominal re-plan \(QP vectors, solve, check\)\s+n=\s*[1-9]\d*\s+median {NUM} ms\s+"
        rf"p99 {NUM} ms\s+max {NUM} ms$",
        rf"^whole step\s+n=\s*100\s+median {NUM} ms\s+p99 {NUM} ms\s+max {NUM} ms$",
        r"^QP counters \(.*\): \[\d+, \d+, \d+, \d+\]$",
    ],
    "bench_qp_solvers": [
        r"^[1-9]\d* QPs recorded over 100 steps \(\d+ distinct H\), \d+ variables",
        rf"^DAQP on every row \(workspace kept\)\s+{NUM}ms\s+{NUM}ms\s+{NUM}ms\s+0\s",
        rf"^DAQP on working rows \(grown\)\s+{NUM}ms\s+{NUM}ms\s+{NUM}ms\s+0\s",
        rf"^Clarabel \(interior point\)\s+{NUM}ms\s+{NUM}ms\s+{NUM}ms\s+\d+\s",
    ],
    "bench_rmpc_step": [
        rf"^Case 1 rmpc, 50 steps in process: wall {NUM} s$",
        rf"^law step \(RMPCLaw\.step\), B = 1\s+n=\s*50\s+median {NUM} ms\s+p99 {NUM} ms",
        rf"^law step, B = 1, min of 5 passes per step\s+n=\s*50\s+median {NUM} ms",
        rf"^law step per run, batch of B = 4\s+n=\s*20\s+median {NUM} ms",
    ],
    "bench_campaign": [
        rf"^\| exact state \| one run, `simulate` \| {NUM} \({NUM}\) \|$",
        rf"^\| implementable \| a batch of 2, `simulate_batch` \| {NUM} \({NUM}\) \|$",
        rf"^\| implementable \| campaign, 1 worker \| {NUM} \({NUM}\) \|$",
        rf"^\| implementable \| share of the re-plans .* \| {NUM} % \|$",
    ],
    "bench_certificate": [
        rf"^vertex_levels: 256 vertices x 256 corners of W_8 in {NUM} s \({NUM} ms per "
        rf"vertex\); worst level {NUM}$",
        rf"^onset_jumps: [1-9]\d* jumps \(\d+ at corners\) in {NUM} s$",
        rf"^onset_bound: {NUM} s; certified loss {NUM} %",
    ],
    "bench_sil": [
        r"^smoke: earlier commit \S+ skipped",
        rf"^  run 1 working tree: wall\s+{NUM} s, real-time factor\s+{NUM}$",
        rf"^working tree: median real-time factor {NUM}\s",
    ],
    "bench_design": [
        r"^smoke: the scaling code at a tiny size",
        # the closure on 128 vertices: the blocks it held, or why it does not close there
        rf"^ +128 +{NUM} +(\d+|not closed: .+)$",
        rf"^ +10 +{NUM} +\d+ +(\d\.\d+|none found)$",  # the ellipsoid LMI on 10 states
    ],
}
#: Benchmarks that run the built ROS 2 workspace.
ROS = {"bench_sil"}


def _params():
    return [
        pytest.param(name, marks=pytest.mark.ros if name in ROS else (), id=name)
        for name in FIGURES
    ]


@pytest.mark.parametrize("name", _params())
def test_benchmark_smoke_run_prints_its_figures(name):
    cmd = [sys.executable, f"benchmarks/{name}.py", "--smoke"]
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=TIMEOUT_S)
    shown = f"$ {' '.join(cmd)}\n{r.stdout[-4000:]}\n--- stderr ---\n{r.stderr[-4000:]}"
    assert r.returncode == 0, shown
    missing = [p for p in FIGURES[name] if not re.search(p, r.stdout, re.MULTILINE)]
    assert missing == [], shown
