"""Parameter uncertainty of sec. 5.1: the parameter box and seeded draws inside it."""

from __future__ import annotations

import numpy as np

from fahv.model.vehicle import VehicleParams

#: The parameters of the box of sec. 5.1 (the parameter box) and their relative bounds.
PAPER_UNCERTAINTY = {
    "m": 0.10,
    "I_yy": 0.10,
    "S": 0.01,
    "z_T": 0.01,
    "c_bar": 0.01,
    "c_e": 0.03,
    "beta_1": 0.03,
    "beta_3": 0.03,
    "beta_5": 0.03,
    "beta_7": 0.03,
}


def perturb(vp: VehicleParams, rel: dict[str, float], signs: dict[str, float]) -> VehicleParams:
    """Parameters with p -> p (1 + s_p rel_p) for s_p in [-1, 1] (parameter box, sec. 5.1).

    Raises
    ------
    ValueError
        If a name is not a parameter or |s_p| > 1.
    """
    changes = {}
    for name, r in rel.items():
        if not hasattr(vp, name):
            raise ValueError(f"uncertainty: unknown parameter '{name}'")
        s = float(signs.get(name, 0.0))
        if abs(s) > 1.0:
            raise ValueError(f"uncertainty: sign/fraction for '{name}' must be in [-1, 1]")
        changes[name] = getattr(vp, name) * (1.0 + s * r)
    return vp.replace(**changes)


def perturbed_params(vehicle, seed: int, scale: float) -> dict[str, float]:
    """Seeded parameter set inside the parameter box of sec. 5.1.

    Each parameter p of `fahv.plant.PAPER_UNCERTAINTY` becomes
    p (1 + s_p scale rel_p), s_p ~ U(-1, 1) from `numpy.random.default_rng(seed)`
    in the order of that table. Returns {name: value}.
    """
    rng = np.random.default_rng(seed)
    rel = {k: v * scale for k, v in PAPER_UNCERTAINTY.items()}
    signs = {k: float(rng.uniform(-1.0, 1.0)) for k in PAPER_UNCERTAINTY}
    vp = perturb(vehicle.params, rel, signs)
    return {k: float(getattr(vp, k)) for k in PAPER_UNCERTAINTY}
