"""Store a design's eight-state pair for the independent tests (tests/data/*.npz).

Usage: python scripts/export_pair.py ARTEFACTS OUT.npz

``fahv design`` of a case with ``tube.form: eight_state`` records its closed pair in the
design summary (``certificate``: W_8, the bound, H, the boxes, the parameter directions'
column scale) and F, N in the arrays. This writes them in the layout of the stored pairs
of tests/data (keys W, F, N, H, moves, lam, w_design, lo, hi, other_half, nominal_lo,
nominal_hi, nominal_other_half, k, rho_min, col_scale, bound, level), so that
tests/design/test_along_nominal.py rebuilds the pair's vertex data with its own code and
re-checks the certificate (item 7 of issue 20: 100 000 true one-step errors inside W_8,
and the exact level over the vertices).
"""

import json
import sys
from pathlib import Path

import numpy as np


def main() -> None:
    """Export the pair of the artefact folder ``sys.argv[1]`` to ``sys.argv[2]``."""
    if len(sys.argv) != 3:
        sys.exit(__doc__.splitlines()[2])
    art, out = Path(sys.argv[1]), Path(sys.argv[2])
    meta = json.loads((art / "design.json").read_text())
    cert, case = meta["summary"]["certificate"], meta["case"]
    if cert.get("form") != "eight_state" or "col_scale" not in cert:
        sys.exit(f"{art}: not an eight-state design with its column scale recorded")
    with np.load(art / "design.npz") as z:
        F, N, w_max = z["F"][:, 1:], z["N"][1:, 1:], z["w_max"]
    box, nominal = cert["scheduling_box"], cert["nominal_box"]
    np.savez(
        out,
        W=np.asarray(cert["W_8"]),
        F=F,
        N=N,
        H=cert["H_ft"],
        moves=cert["moves"],
        lam=cert["lam"],
        w_design=w_max,
        lo=np.asarray(box["lo"]),
        hi=np.asarray(box["hi"]),
        other_half=np.asarray(box["other_half"]),
        nominal_lo=np.asarray(nominal["lo"]),
        nominal_hi=np.asarray(nominal["hi"]),
        nominal_other_half=np.asarray(nominal["other_half"]),
        k=case["eight_state"]["k"],
        rho_min=case["tube"]["rho_min"],
        col_scale=np.asarray(cert["col_scale"]),
        bound=np.asarray(cert["bound"]),
        level=cert["level"],
    )
    print(f"{out}: k = {case['eight_state']['k']}, level {cert['level']:.6f}, W_8 "
          + " ".join(f"{w:.3g}" for w in cert["W_8"]))  # fmt: skip


if __name__ == "__main__":
    main()
