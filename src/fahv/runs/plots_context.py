"""A run as its figures need it: legend label, limits, notch, fault onset, time window.

`fahv plot` reads each run once into a `PlottedRun`: the closed-loop histories
(`fahv.loop.simulate.RunResult`) with what the figures mark on them, taken from
the run itself: the actuator limits of the vehicle it was made with (sec. 5.1), the
tightened input limits u_lo, u_hi of eq. (30) and the notch filter (eq. 38) from its
parameter file, the flexible-mode frequencies omega_flex from its design, the onset
of its fault (`fault_t_onset` of the metadata, none for the fault kind `none`).
The legend label is the run's scenario and variant (`run_labels`).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from fahv.errors import FahvError
from fahv.loop.simulate import RunResult
from fahv.model.vehicle import InputLimits, load_vehicle
from fahv.runs.bag import run_result_of
from fahv.sil.workspace import ROOT
from fahv.spec.plant_dispersion import rate_limit_factor
from fahv.spec.store import design_dir


@dataclasses.dataclass
class PlottedRun:
    """One run of a figure with what the figure marks on it.

    Attributes
    ----------
    label : str
        Legend label (`run_labels`).
    run : RunResult
        The run's histories, N steps.
    limits : InputLimits or None
        Actuator limits of the run's vehicle (sec. 5.1) [-, rad], its servos' rate
        limits times the run's `servo_rate_limit_factor` [1/s, rad/s].
    u_lo, u_hi : (2,) ndarray or None
        Tightened input limits of eq. (30) the nominal input keeps to [-, rad] (None
        for a law without them or a run without its parameter file).
    omega_z : float or None
        Centre frequency of the notch filter on q (eq. 38) [rad/s]; None when the run
        has no notch (`notch_filter` disabled).
    omega_flex : (2,) ndarray or None
        Flexible-mode frequencies of the run's design at its initial trim [rad/s]
        (None when the design is not found).
    t_onset : float or None
        Fault onset [s] (None: no fault).
    """

    label: str
    run: RunResult
    limits: InputLimits | None = None
    u_lo: np.ndarray | None = None
    u_hi: np.ndarray | None = None
    omega_z: float | None = None
    omega_flex: np.ndarray | None = None
    t_onset: float | None = None


def run_labels(paths, metadata) -> list[str]:
    """Legend labels of overlaid runs: `"<scenario> / <variant>"` from the metadata.

    Runs of the same scenario and variant are told apart by their names in
    parentheses (the folder, or the .mcap file without suffix; with the parent folder
    when two such names are equal), a run given twice by its position (`[2]`).

    Parameters
    ----------
    paths : sequence of path
        Run folders or .mcap files, in drawing order.
    metadata : sequence of mapping
        Run metadata of each run (keys `case`, the scenario name, and `variant`;
        `?` where missing).

    Returns
    -------
    list of str
        One distinct label per run, in the order of `paths`.

    Raises
    ------
    ValueError
        If `paths` and `metadata` differ in length.
    """
    paths, metadata = [Path(p) for p in paths], list(metadata)
    if len(paths) != len(metadata):
        raise ValueError(f"{len(paths)} runs but {len(metadata)} metadata")
    base = [f"{m.get('case', '?')} / {m.get('variant', '?')}" for m in metadata]
    where = [p.resolve() for p in paths]
    names = [p.stem if p.suffix == ".mcap" else w.name for p, w in zip(paths, where, strict=True)]
    clash = {n for n in names if len({w for w, m in zip(where, names, strict=True) if m == n}) > 1}
    names = [f"{w.parent.name}/{n}" if n in clash else n
             for w, n in zip(where, names, strict=True)]  # fmt: skip
    told = {b for b in base if len({n for c, n in zip(base, names, strict=True) if c == b}) > 1}
    out = [f"{b} ({n})" if b in told else b for b, n in zip(base, names, strict=True)]
    return [n if out.count(n) == 1 else f"{n} [{out[:i].count(n) + 1}]"
            for i, n in enumerate(out)]  # fmt: skip


def _node(params: dict | None, node: str) -> dict:
    """The `ros__parameters` of one node of a parameter file ({} if absent)."""
    return ((params or {}).get(node) or {}).get("ros__parameters") or {}


def _flexible_modes(metadata: dict, vehicle) -> np.ndarray | None:
    """omega_flex (2,) [rad/s] of the run's stored design (None if it is not found)."""
    name, file = metadata.get("design"), metadata.get("design_file")
    if not name or not file:
        return None
    for base in (Path(file), ROOT / file):
        npz = design_dir(base, str(name), vehicle=vehicle) / "design.npz"
        try:
            with np.load(npz) as z:
                return np.asarray(z["omega_flex"], float)
        except (OSError, KeyError, ValueError):
            continue
    return None


def fault_onset(metadata: dict) -> float | None:
    """Onset [s] of a run's fault from its metadata (None: no fault, or not recorded).

    Parameters
    ----------
    metadata : mapping
        Run metadata (`fault_kind`, `fault_t_onset`).

    Returns
    -------
    float or None
        `fault_t_onset` unless the fault kind is `none` or the onset is not finite.
    """
    if metadata.get("fault_kind", "none") in ("none", None):
        return None
    try:
        t = float(metadata["fault_t_onset"])
    except (KeyError, TypeError, ValueError):
        return None
    return t if math.isfinite(t) else None


def plotted_run(rec, label: str) -> PlottedRun:
    """The `PlottedRun` of a recorded run.

    Parameters
    ----------
    rec : fahv.runs.bag.Recording
        The run file's content.
    label : str
        Its legend label.

    Returns
    -------
    PlottedRun
        Limits from the run's vehicle file (packaged if none recorded), u_lo, u_hi and
        the notch from its parameter file (`nominal_trajectory`, `notch_filter`),
        omega_flex from its design, the onset from the metadata.

    Raises
    ------
    FahvError
        If the run holds no complete step.
    """
    run = run_result_of(rec)
    if run.t.size == 0:
        raise FahvError(f"{rec.path}: no complete step of the loop topics to plot")
    meta = rec.metadata
    vehicle = load_vehicle(meta.get("vehicle_file") or None)
    params = rec.params()
    nom, notch = _node(params, "nominal_trajectory"), _node(params, "notch_filter")
    u_lo, u_hi = nom.get("u_lo"), nom.get("u_hi")
    return PlottedRun(
        label=label,
        run=run,
        limits=vehicle.limits.with_rate_factor(rate_limit_factor({}, params)),
        u_lo=None if u_lo is None else np.asarray(u_lo, float),
        u_hi=None if u_hi is None else np.asarray(u_hi, float),
        omega_z=float(notch["omega_z"]) if notch.get("enabled") else None,
        omega_flex=_flexible_modes(meta, vehicle),
        t_onset=fault_onset(meta),
    )


#: Arrays of a RunResult that are counts over the whole run, not per step.
_PER_RUN = ("lmi_counts", "qp_counts")


def clip_run(run: RunResult, t0: float | None = None, t1: float | None = None) -> RunResult:
    """The steps of a run with t0 <= t <= t1 (a bound None: no bound on that side).

    Parameters
    ----------
    run : RunResult
        N steps.
    t0, t1 : float or None
        Window [s], simulated time.

    Returns
    -------
    RunResult
        Every per-step array cut to the window; counts and info kept.

    Raises
    ------
    FahvError
        If t1 < t0, or no step lies in the window.
    """
    lo = -math.inf if t0 is None else float(t0)
    hi = math.inf if t1 is None else float(t1)
    if hi < lo:
        raise FahvError(f"time window [{lo:g}, {hi:g}] s: t1 is before t0")
    keep = (run.t >= lo) & (run.t <= hi)
    if not keep.any():
        raise FahvError(
            f"no step in the time window [{lo:g}, {hi:g}] s (the run spans "
            f"{run.t[0]:g} to {run.t[-1]:g} s)"
        )
    cut = {
        f.name: getattr(run, f.name)[keep]
        for f in dataclasses.fields(run)
        if f.name not in _PER_RUN and isinstance(getattr(run, f.name), np.ndarray)
    }
    return dataclasses.replace(run, **cut)


def clip_runs(runs: list, t0: float | None = None, t1: float | None = None) -> list:
    """Each `PlottedRun` with its run cut to [t0, t1] (`clip_run`).

    Parameters
    ----------
    runs : list of PlottedRun
    t0, t1 : float or None
        Window [s].

    Returns
    -------
    list of PlottedRun
        New objects; the inputs are unchanged.

    Raises
    ------
    FahvError
        If a run has no step in the window.
    """
    return [dataclasses.replace(r, run=clip_run(r.run, t0, t1)) for r in runs]
