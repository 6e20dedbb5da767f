"""Wall time of ``fahv design``, today's code beside an earlier commit's, in one session.

The machine's speed varies between hours and machines of the same kind, so the figure
that means something is the ratio of two designs timed back to back here. The earlier
commit is checked out into a temporary git worktree and run with its own sources on the
same virtual environment (its design file given as it named it then).

Usage::

    .venv/bin/python benchmarks/bench_design.py \\
        [--design offline_design/designs/cm_certified.yaml] \\
        [--before e33c49c --before-file offline_design/case1.yaml] [--keep DIR]

Prints one line per design (wall time, design hash, whether the certified arrays are
identical) and the ratio. Each design runs in its own process on one BLAS thread.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: The arrays a design certifies (compared between the two runs; x0 and omega_flex
#: follow the design point, the rest must not move).
CERTIFIED = ("A", "B", "w_max", "F", "N", "K", "Q", "u_lo", "u_hi", "trim_x", "trim_u")


def run_design(src: Path, cwd: Path, design_file: str, out: Path) -> float:
    """Run ``fahv design design_file --out out`` with the sources in ``src``; wall seconds."""
    env = {**os.environ, "PYTHONPATH": str(src), "OPENBLAS_NUM_THREADS": "1"}
    code = "import sys; from fahv.cli import main; sys.exit(main(sys.argv[1:]))"
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", code, "design", design_file, "--out", str(out)],
                         cwd=cwd, env=env, capture_output=True, text=True)  # fmt: skip
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        sys.exit(f"design of {design_file} in {cwd} failed:\n{res.stderr[-3000:]}")
    return wall


def main() -> int:
    """Time the earlier commit's design and today's, print both and their ratio."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--design", default="offline_design/designs/cm_certified.yaml")
    ap.add_argument("--before", default="e33c49c", help="earlier commit ('' : skip it)")
    ap.add_argument("--before-file", default="offline_design/case1.yaml",
                    help="the design's file as the earlier commit named it")  # fmt: skip
    ap.add_argument("--keep", type=Path, default=None,
                    help="copy today's design folder here (e.g. to ship it)")  # fmt: skip
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        times = {}
        if args.before:
            tree = tmp / "before"
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree),
                            args.before], check=True, capture_output=True)  # fmt: skip
            try:
                times["before"] = run_design(tree / "src", tree, args.before_file, tmp / "b")
            finally:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                                str(tree)], capture_output=True)  # fmt: skip
            print(f"before ({args.before}, {args.before_file}): {times['before']:.1f} s wall")
        times["after"] = run_design(ROOT / "src", ROOT, args.design, tmp / "a")
        print(f"after (working tree, {args.design}): {times['after']:.1f} s wall")
        if args.keep is not None:
            shutil.copytree(tmp / "a", args.keep, dirs_exist_ok=True)
        if "before" in times:
            with np.load(tmp / "b" / "design.npz") as b, np.load(tmp / "a" / "design.npz") as a:
                same = [k for k in CERTIFIED if k in a and k in b and np.array_equal(a[k], b[k])]
            print(f"ratio after / before: {times['after'] / times['before']:.2f}; certified "
                  f"arrays identical: {len(same)} of {len(CERTIFIED)} "
                  f"({', '.join(same)})")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
