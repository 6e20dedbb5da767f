"""Wall time of the offline design of a case (issue 3 target: Case 1 under 5 minutes).

Usage: .venv/bin/python benchmarks/bench_design.py [offline_design/case1_vertex.yaml]
"""

import sys
import time
import warnings

from fahv.design.case import load_case
from fahv.design.pipeline import run_design

warnings.filterwarnings("ignore", message="Solution may be inaccurate")
path = sys.argv[1] if len(sys.argv) > 1 else "offline_design/case1_vertex.yaml"
t0 = time.perf_counter()
design = run_design(load_case(path), log=lambda *a: None)
wall = time.perf_counter() - t0
print(f"design of {path}: {wall:.1f} s wall (target < 300 s), hash {design.summary['design_hash']}")
