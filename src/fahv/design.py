"""Offline design of a case: case file -> certified artefacts and a ROS 2 parameter file.

Steps (paper sec. 3-4, Algorithm 1): notch filter; TP model of the design model (CM
for Case 1, codesigned ECM for Case 2); disturbance set W (eq. 13-19); F and the
invariant tube Z (LMI 24, eq. 25-28) over the healthy and faulty vertices; tightened
inputs (eq. 30, with Z' = tau Z for the adjustable law, eq. 53); trim map; nominal
gain K (LMI 33-35); the DM LPV model of the RMPC baseline; the perturbed plant
parameters. Every certificate is re-checked; nothing is written unless all hold, and
the artefacts are written to a temporary folder renamed into place at the end.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from fahv import __version__
from fahv.case import Case
from fahv.errors import DesignError
from fahv.linearize import classify_modes, linearize
from fahv.notch import NotchFilter
from fahv.params import node_parameters, parameter_file
from fahv.plant import PAPER_UNCERTAINTY, perturb
from fahv.tp_model import build_tp_model
from fahv.trim import trim_map
from fahv.tube.disturbance import DEFAULT_DEV_BOX, DEFAULT_DU_BOX, sample_disturbance
from fahv.tube.feasibility import fault_vertices, input_room
from fahv.tube.feedback import design_tube, verify_tube
from fahv.tube.nominal import design_nominal, verify_nominal
from fahv.vehicle import Q, VehicleParams, load_vehicle


@dataclass
class Design:
    """Artefacts of one case (unscaled units unless stated).

    Attributes
    ----------
    case : dict
        The validated case data.
    arrays : dict[str, ndarray]
        ``A``, ``B`` (R, n, n/m) discrete nominal vertices; ``h_grid``, ``V_grid``,
        ``W_h``, ``W_V`` TP weighting functions; ``Dx``, ``Du`` scales; ``w_max`` (n,)
        W; ``F`` (2, n), ``N`` (n, n) tube; ``K`` (2, n), ``Q`` (n, n) nominal;
        ``u_room``, ``u_n_max`` (2,); ``trim_h``, ``trim_V``, ``trim_x`` (Nh, NV, n),
        ``trim_u`` (Nh, NV, 2); ``rmpc_A``, ``rmpc_B`` (DM vertices);
        ``omega_flex`` (2,) flexible-mode frequencies at the initial trim [rad/s].
    summary : dict
        Scalars: certificates, W breakdown, plant parameters, hash.
    """

    case: dict
    arrays: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)

    @property
    def n_x(self) -> int:
        """Design-model state dimension (9 or 11)."""
        return self.arrays["A"].shape[1]

    def content_hash(self) -> str:
        """sha256 over the case data and every array (hex, first 16 characters)."""
        h = hashlib.sha256(json.dumps(self.case, sort_keys=True, default=str).encode())
        for k in sorted(self.arrays):
            a = np.ascontiguousarray(self.arrays[k])
            h.update(k.encode())
            h.update(str(a.shape).encode())
            h.update(a.tobytes())
        return h.hexdigest()[:16]

    def plant_params(self, vehicle) -> VehicleParams:
        """The perturbed parameter set of the simulated vehicle (summary['plant_params'])."""
        return dataclasses.replace(vehicle.params, **self.summary["plant_params"])


def _notch(case: Case) -> NotchFilter:
    n = case["notch"]
    return NotchFilter(n["omega_z"], n["eps_z"], n["omega_p"], n["eps_p"])


def perturbed_params(vehicle, seed: int, scale: float) -> dict[str, float]:
    """Seeded parameter set inside the uncertainty box of sec. 5.1.

    Each parameter p of :data:`fahv.plant.PAPER_UNCERTAINTY` becomes
    p (1 + s_p scale rel_p), s_p ~ U(-1, 1) from ``numpy.random.default_rng(seed)``
    in the order of that table. Returns {name: value}.
    """
    rng = np.random.default_rng(seed)
    rel = {k: v * scale for k, v in PAPER_UNCERTAINTY.items()}
    signs = {k: float(rng.uniform(-1.0, 1.0)) for k in PAPER_UNCERTAINTY}
    vp = perturb(vehicle.params, rel, signs)
    return {k: float(getattr(vp, k)) for k in PAPER_UNCERTAINTY}


def run_design(case: Case, progress=None, log=print) -> Design:
    """Compute and verify every artefact of ``case``.

    Parameters
    ----------
    case : Case
    progress : callable, optional
        Iterable wrapper for long loops (tqdm).
    log : callable
        Receives one line per step and per certificate.

    Returns
    -------
    Design

    Raises
    ------
    DesignError
        If an LMI is infeasible or a certificate fails (the message names which).
    """
    veh = load_vehicle()
    c = case.data
    kind, Ts = c["design_model"], c["Ts"]
    notch = _notch(case)
    r_h, r_V = c["vertices"]
    n_h, n_V = c["samples"]
    if r_h > n_h or r_V > n_V:
        raise DesignError(f"vertices {c['vertices']} exceed the TP samples {c['samples']}")
    tp = build_tp_model(veh, kind, r_h, r_V, n_h, n_V, notch if kind == "ecm" else None)
    if tp.n_vertices != r_h * r_V:
        raise DesignError(
            f"case asks for {r_h * r_V} vertices, the TP model has {tp.n_vertices}: the "
            "sampled tensor does not have that rank"
        )
    disc = tp.discretize(Ts)
    Dx, Du = tp.state_scale, tp.input_scale
    log(f"TP model: {kind.upper()}, {tp.n_vertices} vertices, Ts = {Ts} s")
    lin = linearize(veh, c["command"]["h0"], c["command"]["V0"], "cm")
    modes = {m.name: m.wn for m in classify_modes(lin.A, veh.params.omega_1, veh.params.omega_2)}
    omega_flex = np.array([modes["flexible 1"], modes["flexible 2"]])
    dev_box = DEFAULT_DEV_BOX
    if kind == "ecm":
        dev_box = np.concatenate([DEFAULT_DEV_BOX, 2.0 * notch.state_scale(Dx[Q])])
    d = c["disturbance"]
    unc = {k: v * c["uncertainty"]["scale"] for k, v in PAPER_UNCERTAINTY.items()}
    W = sample_disturbance(
        veh,
        tp,
        Ts,
        unc,
        1.0,
        dev_box,
        DEFAULT_DU_BOX,
        d["samples"],
        d["seed"],
        d["margin"],
        progress=progress,
        notch=notch if kind == "ecm" else None,
    )
    log(
        f"W: {d['samples']} samples, margin {d['margin']}; dominant source per state: "
        + ", ".join(W.dominant())
    )
    rho_f = c["fault"]["rho_f"] if c["fault"]["kind"] == "loss_of_effectiveness" else 1.0
    Af, Bf = fault_vertices(disc.A, disc.B, rho_f)
    room = input_room(veh)
    tube = design_tube(Af, Bf, W.w_max, Dx, Du, room, tuple(c["tube"]["lam"]))
    eigs = verify_tube(Af, Bf, tube, Dx, Du)
    log(
        f"certificate F, Z (LMI 24 + S-procedure, {Af.shape[0]} vertices incl. rho_f = "
        f"{rho_f}): min eigenvalue {eigs.min():.3e} >= 0, lam = {tube.lam}  OK"
    )
    tau = c["tube"]["tau"]
    u_n_max = room - tau * tube.tightening
    log(
        f"tightened inputs (eq. 30{', 53 with tau = ' + str(tau) if tau < 1 else ''}): "
        f"room {room[0]:.4f} / {np.degrees(room[1]):.3f} deg, tightening "
        f"{tau * tube.tightening[0]:.4f} / {np.degrees(tau * tube.tightening[1]):.3f} deg"
    )
    if np.any(u_n_max <= 0.0):
        raise DesignError(
            f"tightened input set U minus F Z is empty (eq. 30): room {room}, "
            f"tightening {tau * tube.tightening}"
        )
    cmd = c["command"]
    veh.envelope.check(cmd["h0"], cmd["V0"])
    veh.envelope.check(cmd["h_c"], cmd["V_c"])
    tg = c["trim_grid"]
    tm = trim_map(veh, tg[0], tg[1], kind, notch if kind == "ecm" else None)
    x_start, _ = tm(cmd["h0"], cmd["V0"])
    x_end, _ = tm(cmd["h_c"], cmd["V_c"])
    dvec = x_start - x_end
    Dn = Dx * np.maximum(1.0, np.abs(dvec) / Dx)  # command-sized scaling of the nominal LMI
    nominal = design_nominal(disc.A, disc.B, dvec, u_n_max, Dn, u_n_max, c["nominal"]["lam"])
    cert = verify_nominal(disc.A, disc.B, nominal, Dn, u_n_max)
    log(
        f"certificate K (LMI 33-35'): contraction {cert['contraction']:.6f} < 1, input "
        f"ratio {cert['input_ratio']:.4f} <= 1, LMI min eigenvalue "
        f"{cert['lmi34_min_eig']:.2e}, fraction of the command in E(Q) s = {nominal.s:.3f}  OK"
    )
    arrays = {
        "A": disc.A,
        "B": disc.B,
        "h_grid": tp.h_grid,
        "V_grid": tp.V_grid,
        "W_h": tp.W_h,
        "W_V": tp.W_V,
        "Dx": Dx,
        "Du": Du,
        "w_max": W.w_max,
        "F": tube.F,
        "N": tube.N,
        "K": nominal.K,
        "Q": nominal.Q,
        "u_room": room,
        "u_n_max": u_n_max,
        "trim_h": tm.h_grid,
        "trim_V": tm.V_grid,
        "trim_x": tm.x_r,
        "trim_u": tm.u_r,
        "omega_flex": omega_flex,
    }
    if "rmpc" in c["variants"]:
        rv = c["rmpc"]["vertices"]
        dm = build_tp_model(veh, "dm", rv[0], rv[1], n_h, n_V)
        dmd = dm.discretize(Ts)
        arrays["rmpc_A"], arrays["rmpc_B"] = dmd.A, dmd.B
    summary = {
        "code_version": __version__,
        "n_vertices": int(tp.n_vertices),
        "W_parts": {k: v.tolist() for k, v in W.parts.items()},
        "W_dominant": W.dominant(),
        "tube": {
            "lam": tube.lam,
            "min_eig": float(eigs.min()),
            "tightening": (tau * tube.tightening).tolist(),
            "z_box": tube.z_box.tolist(),
        },
        "nominal": {**cert, "s": nominal.s, "lam": nominal.lam},
        "plant_params": perturbed_params(veh, c["uncertainty"]["seed"], c["uncertainty"]["scale"]),
    }
    design = Design(c, arrays, summary)
    design.summary["design_hash"] = design.content_hash()
    return design


def save_design(design: Design, out_dir: str | Path) -> Path:
    """Write ``design.npz``, ``design.json`` and ``params.yaml`` into out_dir atomically.

    The files are written to a temporary sibling folder that replaces ``out_dir`` only
    when all of them are complete, so a failure never leaves half an artefact set.
    Returns out_dir.
    """
    out = Path(out_dir)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        np.savez(tmp / "design.npz", **design.arrays)
        (tmp / "design.json").write_text(
            json.dumps({"case": design.case, "summary": design.summary}, indent=2, default=list)
        )
        (tmp / "params.yaml").write_text(
            yaml.safe_dump(parameter_file(node_parameters(design)), sort_keys=False, width=120)
        )
        if out.exists():
            shutil.rmtree(out)
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def load_design(out_dir: str | Path) -> Design:
    """Read the artefacts written by :func:`save_design`.

    Raises
    ------
    DesignError
        If a file is missing or the content hash does not match.
    """
    out = Path(out_dir)
    try:
        meta = json.loads((out / "design.json").read_text())
        with np.load(out / "design.npz") as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, KeyError) as exc:
        raise DesignError(f"design artefacts in {out} are missing or unreadable: {exc}") from None
    design = Design(meta["case"], arrays, meta["summary"])
    if design.content_hash() != meta["summary"].get("design_hash"):
        raise DesignError(f"design artefacts in {out} do not match their hash: re-run fahv design")
    return design


__all__ = [
    "Design",
    "perturbed_params",
    "run_design",
    "save_design",
    "load_design",
]
