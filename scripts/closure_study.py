"""W-Z closure study of the Case 1 tube (docs/control_design.md, "Is the certificate true?").

Iterates W <- max(W, bound of the one-step disturbance over the domain of Z(W)) with
the tube LMI (24) re-solved each time, for a chosen domain: scheduling points, the
nominal input rows around the scheduling trim, a scale of the nominal state ranges
the nominal MPC allows, the nominal vehicle or the whole parameter box, and the
starting W as a fraction of the design's. Prints per iteration the tightening, the
alpha extent of Z and bound / W per row; stops when the pair closes (bound <= W) or
the tube LMI becomes infeasible.

Usage (after `fahv design offline_design/case1.yaml`):
    .venv/bin/python scripts/closure_study.py SCHEDULES DPHI DDELTA_E_DEG NOMINAL_SCALE \
        {nominal,box} W0_FRACTION [ITERATIONS]
e.g. scripts/closure_study.py 1 0.1 3 1.0 box 1.0     (the MPC's ranges: diverges)
     scripts/closure_study.py 1 0.01 0.3 0.1 nominal 0.1
"""

import sys
import warnings
from pathlib import Path

import numpy as np

from fahv.design.artefacts import load_design
from fahv.design.certificate import (
    CertificateDomain,
    bound_disturbance,
    nominal_half_widths,
    schedule_points,
)
from fahv.design.disturbance import DEFAULT_DEV_BOX
from fahv.design.feasibility import fault_vertices, input_room
from fahv.errors import DesignError
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import TrimMap
from fahv.model.vehicle import load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.synthesis.feedback import design_tube

ROOT = Path(__file__).resolve().parents[1]


def main(argv):
    """Run the iteration of the module docstring with the command-line arguments."""
    n_s, dphi, dde, nom_scale, veh_kind, w0 = argv[:6]
    iterations = int(argv[6]) if len(argv) > 6 else 12
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    d = load_design(ROOT / "offline_design" / "artefacts" / "case1")
    a, c = d.arrays, d.case
    veh = load_vehicle()
    r_h, r_V = c["vertices"]
    tp = build_tp_model(veh, "cm", r_h, r_V, *c["samples"])
    tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
    disc = tp.discretize(c["Ts"])
    rho = c["tube"]["rho_min"]
    Af, Bf = fault_vertices(disc.A, disc.B, rho)
    room_f = input_room(veh, rho_f=rho)
    du = np.array([float(dphi), np.radians(float(dde))])
    nominal, notes = nominal_half_widths(c["mpc"], DEFAULT_DEV_BOX)
    nominal = nominal * float(nom_scale)
    unc = dict(PAPER_UNCERTAINTY) if veh_kind == "box" else {}
    W = a["w_max"] * float(w0)
    for it in range(iterations):
        try:
            tube = design_tube(Af, Bf, W, tp.state_scale, tp.input_scale, room_f,
                               tuple(c["tube"]["lam"]))  # fmt: skip
        except DesignError as exc:
            print(f"iteration {it}: tube LMI infeasible ({exc})")
            return
        bounds = []
        for s in schedule_points(veh.envelope, int(n_s)):
            u_r = tm(*s)[1]
            t = tube.tightening
            dom = CertificateDomain(np.array([s]), nominal + tube.z_box, nominal, u_r - du - t,
                                    u_r + du + t, unc, (rho, 1.0), c["Ts"],
                                    c["plant_substeps"], notes)  # fmt: skip
            bounds.append(bound_disturbance(dom, veh, tp, tm).w_bound)
        Wb = np.max(bounds, axis=0)
        print(
            f"iteration {it}: tightening {tube.tightening[0]:.3f} / "
            f"{np.degrees(tube.tightening[1]):.2f} deg, alpha extent of Z "
            f"{np.degrees(tube.z_box[2]):.2f} deg, bound / W: "
            + " ".join(f"{r:.2f}" for r in Wb / W),
            flush=True,
        )
        if np.all(Wb <= W):
            print("closed: the disturbance over the domain of Z lies inside W")
            return
        W = np.maximum(W, Wb)
    print("not closed within the iterations")


if __name__ == "__main__":
    main(sys.argv[1:])
