"""Records of closed eight-state tube sets kept under tests/data, rebuilt by the tests.

A record holds what a tube set's certificate is re-checked from: W_8, F_8, N_8, H, the
reset's moves, lam, the sampled W that scales the parameter directions (``w_design``),
the scheduling box (``lo``, ``hi``, ``other_half``), the nominal box (``nominal_*``), k,
rho_min, the directions' column scale, W_8's bound and, for a design's own tube set,
its exact level. The tests rebuild the vertex data with the library's code from it.

- ``closed_tube_h_reset.npz``: a tube set of 4096 vertices (k = 5) on the box the
  certified design of Case 1 reproduces within rounding, with ``steady_active``, the
  vertices its onset's steady set held (where the onset test's constraint generation
  starts, `steady_start` of `fahv.onset.bound.onset_bound`);
- ``closed_tube_h_reset_tau.npz``: a tube set of the adjustable law (tau = 0.8, 8192
  vertices);
- ``cm_certified``: the shipped certified design's own tube set (k = 7, 16384
  vertices), read from ``offline_design/designs/cm_certified/`` by
  :func:`record_of_design`: the tests sample the design the product runs.
"""

import json
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
DESIGNS = ROOT / "offline_design" / "designs"


def load_record(name: str) -> dict:
    """The record ``tests/data/<name>`` (.npz), or that of the shipped design ``name``."""
    if name.endswith(".npz"):
        return dict(np.load(DATA / name))
    return record_of_design(DESIGNS / name)


def record_of_design(folder) -> dict:
    """The record of an eight-state design's tube set, from its artefact folder.

    ``fahv design`` stores the tube set in the design summary (``certificate``: W_8, the
    bound, H, the boxes, the directions' column scale) and F, N in the arrays.
    """
    folder = Path(folder)
    meta = json.loads((folder / "design.json").read_text())
    cert, case = meta["summary"]["certificate"], meta["case"]
    if cert.get("form") != "eight_state" or "col_scale" not in cert:
        raise ValueError(f"{folder}: not an eight-state design with its column scale recorded")
    with np.load(folder / "design.npz") as z:
        F, N, w_max = z["F"][:, 1:], z["N"][1:, 1:], z["w_max"]
    box, nominal = cert["scheduling_box"], cert["nominal_box"]
    return {
        "W": np.asarray(cert["W_8"]),
        "F": F,
        "N": N,
        "H": cert["H_ft"],
        "moves": cert["moves"],
        "lam": cert["lam"],
        "w_design": w_max,
        "lo": np.asarray(box["lo"]),
        "hi": np.asarray(box["hi"]),
        "other_half": np.asarray(box["other_half"]),
        "nominal_lo": np.asarray(nominal["lo"]),
        "nominal_hi": np.asarray(nominal["hi"]),
        "nominal_other_half": np.asarray(nominal["other_half"]),
        "k": case["eight_state"]["k"],
        "rho_min": case["tube"]["rho_min"],
        "col_scale": np.asarray(cert["col_scale"]),
        "bound": np.asarray(cert["bound"]),
        "level": cert["level"],
    }


def write_record(folder, out) -> None:
    """Write :func:`record_of_design` of the artefact folder ``folder`` to ``out`` (.npz)."""
    np.savez(out, **record_of_design(folder))
