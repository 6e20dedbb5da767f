"""Many runs of one variant at once: the runs are stacked, the loop is the one of simulate.

A Monte Carlo campaign runs the same designed case hundreds of times with other plant
parameters, faults, commands and initial trims (node parameter `overrides`, as
`fahv.loop.simulate.simulate` takes them). `simulate_batch` stacks such
runs and steps them together through `fahv.loop.simulate.Loop`, the very loop
of `simulate`: every node core works on a leading axis of B runs (the plant's RK4
compiled, the QPs of the nominal MPC a loop over the runs inside their class), so
the Python overhead of a step is paid once per batch and a run's numbers are those
of `simulate` -- by construction, there is no second implementation (the tests
still compare the two with `array_equal`).

Grouping
    Runs share a batch when every parameter except their own (`PER_RUN`: the
    plant's parameters, initial state, servo and sensor data, sensor seed and sensor
    fault, the estimator's initial estimate, the command and the initial measured
    state of the nominal part, the whole fault) is the same; other runs go to other
    groups.

Failures
    A run that fails (non-finite state, an infeasible first solve, a bad override)
    gets its exception in the result list; the others go on. The exception of a run
    that failed while stepping carries what it flew before: `exc.partial` is the
    `fahv.loop.simulate.RunResult` of its steps before the failing one (for
    its metrics and figures; None when it failed before step 0 or was never built).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fahv.lanes import Lanes
from fahv.loop.params import controller_node
from fahv.loop.simulate import History, Loop, RunResult, run_info, run_parameters
from fahv.spec.plant_dispersion import PLANT_DISPERSION

#: Node parameters a run may have of its own inside a batch (prefixes end with '.').
PER_RUN = {
    "plant": ("x0", "params.", "stuck", "stuck_onset", "sensor_seed", "sensor_fault.",
              *(f.name for f in PLANT_DISPERSION)),
    "state_estimator": ("x0",),
    "nominal_trajectory": ("x0", "command."),
    "fault_injector": None,  # everything
}


def _own(node: str, name: str) -> bool:
    keys = PER_RUN.get(node, ())
    if keys is None:
        return True
    return any(name == k or (k.endswith(".") and name.startswith(k)) for k in keys)


def shared_signature(p: dict) -> bytes:
    """Bytes of every parameter a run shares with the others of its batch (`PER_RUN`)."""
    parts = []
    for node in sorted(p):
        for name in sorted(p[node]):
            if _own(node, name):
                continue
            parts.append(f"{node}.{name}=".encode() + _value_bytes(p[node][name]))
    return b"\x00".join(parts)


def _value_bytes(v) -> bytes:
    """Bytes that identify a parameter value: its type, shape and every bit of its numbers.

    Arrays and lists of numbers (the flattened matrices of a parameter file) by their
    raw bytes, the rest by `repr` (exact for floats too, but slow on long lists).
    """
    if isinstance(v, (list, tuple)) and v and all(type(e) is float for e in v):
        v = np.asarray(v, dtype=float)
    if isinstance(v, np.ndarray) and v.dtype != object:
        head = f"{type(v).__name__}{v.dtype.str}{v.shape}".encode()
        return head + np.ascontiguousarray(v).tobytes()
    return repr(v).encode()


def simulate_batch(
    design,
    variant: str | None = None,
    overrides: Sequence[dict | None] = (None,),
    duration: float | None = None,
) -> list[RunResult | Exception]:
    """Run B runs of one variant of a designed case, stepped together.

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
    variant : str, optional
        One of the case's variants; its first by default.
    overrides : sequence of dict or None
        Per run, node parameter overrides `{node: {name: value}}` (as
        `fahv.loop.simulate.simulate` takes them); B = its length.
    duration : float, optional
        Simulated time of every run [s]; the case's by default.

    Returns
    -------
    list
        Per run, in order: its `fahv.loop.simulate.RunResult` (identical to
        `simulate(design, variant, duration, overrides=...)`), or the exception
        that run raised (`fahv.errors.RunError` for a non-finite state,
        `fahv.errors.ParameterError` naming the node and key of a bad
        override, ...) with `partial` set (see Failures above). One failing run
        never stops the others.
    """
    variant = design.case["variants"][0] if variant is None else variant
    results: list = [None] * len(overrides)
    params: dict[int, dict] = {}
    groups: dict[bytes, list[int]] = {}
    for i, ov in enumerate(overrides):
        try:
            p = run_parameters(design, variant, duration, ov)
            controller_node(p)
        except Exception as exc:  # noqa: BLE001 - recorded as the run's failure
            exc.partial = None
            results[i] = exc
            continue
        params[i] = p
        groups.setdefault(shared_signature(p), []).append(i)
    for idx in groups.values():
        for i, res in zip(idx, _run_group([params[i] for i in idx], design, variant), strict=True):
            results[i] = res
    return results


def _run_group(runs: list[dict], design, variant: str) -> list[RunResult | Exception]:
    """The runs of one group through one `Loop` (failures per run)."""
    lanes = Lanes(len(runs), strict=False)
    try:
        loop = Loop(runs, lanes)
    except Exception as exc:  # noqa: BLE001 - a bad parameter of one run: build them one by one
        if len(runs) == 1:
            exc.partial = None
            return [exc]
        return [res for r in runs for res in _run_group([r], design, variant)]
    hist = History(loop.n_steps, len(runs), loop.n, loop.n_y)
    with np.errstate(all="ignore"):
        for k in range(loop.n_steps):
            _, state, meas, est, *rest = loop.step(k)
            hist.add(state, *rest, meas=meas, est=est)
    out: list[RunResult | Exception] = []
    for b in range(len(runs)):
        info = run_info(design, variant, loop.Ts, runs[b]["plant"])
        exc = lanes.errors[b]
        if exc is None:
            out.append(hist.result(b, info))
            continue
        k = lanes.failed_step[b]
        exc.partial = hist.result(b, info, k) if k is not None and k > 0 else None
        out.append(exc)
    return out
