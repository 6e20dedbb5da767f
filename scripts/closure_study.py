"""W-Z closure study of the Case 1 tube (docs/control_design.md, "Is the certificate true?").

Iterates W <- max(W, bound of the one-step disturbance over the domain of Z(W)) with
the tube LMI (24) re-solved each time, for a chosen domain: scheduling points, the
nominal input rows around the scheduling trim, a scale of the nominal state ranges
the nominal MPC allows, the nominal vehicle or the whole parameter box, and the
starting W as a fraction of the design's. With ``--directions K`` the tube's vertices
carry the parameter box along its K principal directions
(:func:`fahv.design.certificate.parameter_directions`; the TP vertices shifted to every
corner of the coefficient box) and W bounds only the rest. Prints per iteration the tightening, the
alpha extent of Z and bound / W per row; stops when the pair closes (bound <= W) or
the tube LMI becomes infeasible.

Usage (after `fahv design offline_design/case1_vertex.yaml`):
    .venv/bin/python scripts/closure_study.py SCHEDULES DPHI DDELTA_E_DEG NOMINAL_SCALE \
        {nominal,box} W0_FRACTION [ITERATIONS] [--directions K]
e.g. scripts/closure_study.py 1 0.1 3 1.0 box 1.0     (the MPC's ranges: diverges)
     scripts/closure_study.py 1 0.01 0.3 0.1 nominal 0.1
     scripts/closure_study.py 1 0.1 3 1.0 box 1.0 1 --directions 1
     scripts/closure_study.py 1 0 0 0 box 0.01 12 --directions 3 --rows-by-w --lam 0.995 \
         --grow 1.05     (holding the centre trim: closes)
Options: --directions K (parameter box in the vertices along K directions),
--rows-by-w (directions chosen relative to the design's W row by row), --lam L1,L2
(contraction factors tried), --grow G (W <- max(W, G bound): a fixed point with slack),
--save FILE (the closed pair W, F, N and its domain, .npz).
"""

import dataclasses
import sys
import warnings
from pathlib import Path

import numpy as np

from fahv.design.artefacts import load_design
from fahv.design.certificate import (
    CertificateDomain,
    bound_disturbance,
    nominal_half_widths,
    parameter_directions,
    schedule_points,
    worst_level,
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
    opts = {"--directions": "0", "--lam": "", "--grow": "1.0", "--save": ""}
    for name in opts:
        if name in argv:
            i = argv.index(name)
            opts[name] = argv[i + 1]
            argv = argv[:i] + argv[i + 2 :]
    rows_by_w = "--rows-by-w" in argv
    argv = [v for v in argv if v != "--rows-by-w"]
    k_dirs, grow = int(opts["--directions"]), float(opts["--grow"])
    n_s, dphi, dde, nom_scale, veh_kind, w0 = argv[:6]
    iterations = int(argv[6]) if len(argv) > 6 else 12
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    d = load_design(ROOT / "offline_design" / "artefacts" / "case1_vertex")
    a, c = d.arrays, d.case
    veh = load_vehicle()
    r_h, r_V = c["vertices"]
    tp = build_tp_model(veh, "cm", r_h, r_V, *c["samples"])
    tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
    disc = tp.discretize(c["Ts"])
    rho = c["tube"]["rho_min"]
    lam = tuple(float(v) for v in opts["--lam"].split(",")) if opts["--lam"] else c["tube"]["lam"]
    Af, Bf = fault_vertices(disc.A, disc.B, rho)
    room_f = input_room(veh, rho_f=rho)
    du = np.array([float(dphi), np.radians(float(dde))])
    nominal, notes = nominal_half_widths(c["mpc"], DEFAULT_DEV_BOX)
    nominal = nominal * float(nom_scale)
    unc = dict(PAPER_UNCERTAINTY) if veh_kind == "box" else {}
    W = a["w_max"] * float(w0)
    scheds = schedule_points(veh.envelope, int(n_s))
    dirs = None
    if k_dirs:
        if veh_kind != "box":
            raise SystemExit("--directions needs the parameter box ('box')")
        dirs = parameter_directions(veh, tm, scheds, unc, c["Ts"], c["plant_substeps"],
                                    tp.state_scale, tp.input_scale, k_dirs,
                                    row_scale=a["w_max"] if rows_by_w else None)  # fmt: skip
        Af, Bf = fault_vertices(*dirs.vertices(disc.A, disc.B), rho)
        print(
            f"parameter box in the vertices along {k_dirs} direction(s): RMS singular values "
            + " ".join(f"{s:.3g}" for s in dirs.singular_values[:4])
            + f"; {Af.shape[0]} vertices",
            flush=True,
        )
    for it in range(iterations):
        try:
            tube = design_tube(Af, Bf, W, tp.state_scale, tp.input_scale, room_f, tuple(lam),
                               w_ref=a["w_max"])  # fmt: skip
        except DesignError as exc:
            print(f"iteration {it}: tube LMI infeasible ({exc})")
            return
        bounds = []
        for si, s in enumerate(scheds):
            u_r = tm(*s)[1]
            t = tube.tightening
            dom = CertificateDomain(np.array([s]), nominal + tube.z_box, nominal, u_r - du - t,
                                    u_r + du + t, unc, (rho, 1.0), c["Ts"],
                                    c["plant_substeps"], notes)  # fmt: skip
            d_s = None
            if dirs is not None:
                d_s = dataclasses.replace(
                    dirs,
                    schedules=scheds[si : si + 1],
                    corner_linear=dirs.corner_linear[si : si + 1],
                )
            bounds.append(bound_disturbance(dom, veh, tp, tm, directions=d_s).w_bound)
        Wb = np.max(bounds, axis=0)
        print(
            f"iteration {it}: tightening {tube.tightening[0]:.3f} / "
            f"{np.degrees(tube.tightening[1]):.2f} deg, alpha extent of Z "
            f"{np.degrees(tube.z_box[2]):.2f} deg, bound / W: "
            + " ".join(f"{r:.3f}" for r in Wb / W),
            flush=True,
        )
        if np.all(Wb <= W):
            level, _ = worst_level(Af, Bf, tube.F, tube.N, W)
            print(
                "closed: the disturbance over the domain of Z lies inside W (slack per row "
                + " ".join(f"{s:+.3f}" for s in (W - Wb) / W)
                + f"); exact worst one-step level over {Af.shape[0]} vertices and the corners "
                f"of W: {level:.5f} (margin {1 - level:.2e}); W / design W: "
                + " ".join(f"{r:.4f}" for r in W / a["w_max"])
                + "; support of Z: "
                + " ".join(f"{z:.3g}" for z in tube.z_box)
                + f"; lam {tube.lam}"
            )
            if opts["--save"]:
                np.savez(opts["--save"], W=W, F=tube.F, N=tube.N, lam=tube.lam,
                         w_design=a["w_max"], schedules=scheds, rho_min=rho, k=k_dirs,
                         rows_by_w=rows_by_w, dphi=float(dphi), ddelta_e_deg=float(dde),
                         nominal=nominal)  # fmt: skip
                print(f"closed pair written to {opts['--save']}")
            return
        W = np.maximum(W, grow * Wb)
    print("not closed within the iterations")


if __name__ == "__main__":
    main(sys.argv[1:])
