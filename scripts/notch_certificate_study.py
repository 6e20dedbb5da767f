"""The eight-state tube's loop through the notch on q, certified in its own states (issue 20).

For a case with ``tube.form: eight_state`` and its saved design, the loop that feeds q
through the notch (eq. 38) is checked in its own states, [e_8; chi]: an ellipsoid RPI
for W_8 at every one of the design's vertices, whose projection on e_8 lies in s Z_8 and
whose input support stays within F_8 Z_8's (:func:`fahv.design.certificate.notch_tube`),
for the case's notch and for other pole dampings eps_p. Certified means every assumption
W_8 was bounded under still holds with the filter in the loop (s <= 1, level <= 1,
supports within the tightening).

The vertices are the design's own: the design pipeline is run up to the pair's closure
(about 30 s), which is then skipped; F_8, N_8 and W_8 come from the saved design.

    python scripts/notch_certificate_study.py offline_design/case1.yaml 0.5 0.1

Each eps_p takes 1-10 min (constraint generation on 4096 vertices, two cores). With
``--check`` the ellipsoids stored in scripts/data/notch_ellipsoids_case1.npz (found by
exploratory solves, 2026-11-24) are re-checked exactly on the design's vertices instead
(:func:`fahv.design.certificate.notch_certificate`); F_8, N_8 and W_8 then come from
that file:

    python scripts/notch_certificate_study.py offline_design/case1.yaml --check
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import fahv.design.eight_state as es
from fahv.design.case import load_case
from fahv.design.certificate import notch_certificate, notch_tube
from fahv.design.pipeline import run_design
from fahv.model.notch import NotchFilter

ROOT = Path(__file__).resolve().parents[1]


class _Captured(Exception):
    def __init__(self, nv, nominal):
        super().__init__("vertices captured")
        self.nv, self.nominal = nv, nominal


def design_nominal_vertices(case) -> tuple[es.NominalVertices, es.SchedulingBox]:
    """The vertex data and the nominal box the case's pair is closed over (design run up to it)."""

    def capture(nv, nominal, *args, **kwargs):
        raise _Captured(nv, nominal)

    closure, es.close_pair = es.close_pair, capture
    try:
        run_design(case, log=lambda line: None)
    except _Captured as got:
        return got.nv, got.nominal
    finally:
        es.close_pair = closure
    raise RuntimeError("the design never reached the pair's closure (not an eight-state case?)")


def design_vertices(case) -> tuple[np.ndarray, np.ndarray]:
    """The (A, B) vertices (R, 9, 9), (R, 9, 2) the case's pair is closed over."""
    return design_nominal_vertices(case)[0].vertices()


def check(case, A, B) -> None:
    """Re-check the stored ellipsoids (module docstring) and print their lines."""
    data = np.load(ROOT / "scripts" / "data" / "notch_ellipsoids_case1.npz")
    n = case["notch"]
    for key in sorted(k for k in data.files if k.startswith("P_eps_p_")):
        nf = NotchFilter(n["omega_z"], n["eps_z"], n["omega_p"], float(key[8:]))
        loop = notch_certificate(A[:, 1:, 1:], B[:, 1:, :], data["F8"], data["N8"], data["W8"],
                                 nf, case["Ts"], 3, data[key], "tube_mpc")  # fmt: skip
        print(f"stored {key}: {loop.line()}", flush=True)


def main(argv: list[str]) -> int:
    """Print the certificate line of each eps_p (argv: case file, eps_p values or --check)."""
    case = load_case(argv[0])
    if argv[1:] == ["--check"]:
        check(case, *design_vertices(case))
        return 0
    art = ROOT / "offline_design" / "artefacts" / case["name"]
    arrays = np.load(art / "design.npz")
    cert = json.loads((art / "design.json").read_text())["summary"]["certificate"]
    F8, N8, W8 = arrays["F"][:, 1:], arrays["N"][1:, 1:], np.asarray(cert["W_8"])
    t0 = time.perf_counter()
    A, B = design_vertices(case)
    print(f"{A.shape[0]} vertices of {case['name']} in {time.perf_counter() - t0:.0f} s")
    n = case["notch"]
    for eps_p in [float(v) for v in argv[1:]] or [n["eps_p"]]:
        nf = NotchFilter(n["omega_z"], n["eps_z"], n["omega_p"], eps_p)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # cvxpy's "solution may be inaccurate": re-checked
            loop = notch_tube(A[:, 1:, 1:], B[:, 1:, :], F8, N8, W8, nf, case["Ts"], 3,
                              cert["lam"], "tube_mpc")  # fmt: skip
        print(f"{loop.line()} [{time.perf_counter() - t0:.0f} s]", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
