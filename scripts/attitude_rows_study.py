"""Settling against the width of the attitude rows: what item 5 costs campaign (a).

Usage: python scripts/attitude_rows_study.py CAMPAIGN_DIR [ROWS ...] [--theta ROWS_THETA]
                                              [--trace INDEX]

A campaign folder (``fahv campaign ...``) holds every run's dispersed values and the
design it ran with. This script takes the runs of that campaign that settled later
than the campaign's own ``settling_s`` and simulates them again in process, with the
nominal MPC's attitude rows (node parameter ``mpc.att_max``, alpha and theta) set to
each width given, everything else as recorded (the same kernels as the campaign:
:func:`fahv.loop.simulate.simulate` with the run's overrides from
:func:`fahv.campaign.draws.overrides`). It prints, per width, how many of those runs
still settle late, and their largest and median settling time [s].

Rows wider than the certified bound ``0.5 deg - support of Z_8`` are NOT certified:
the sweep measures what settling within 60 s would need, not a design.

With ``--theta`` only the theta row is widened (alpha stays at the design's value):
theta's own certified bound, 0.5 deg less Z_8's theta support.

With ``--trace INDEX`` it prints one run's transient at the design's rows and at each
width: h - h_c, V - V_c, the set point's offsets, alpha and theta from the set point's
nominal trim (what the metric measures), the flight-path angle and the inputs.

docs/control_design.md, "Settling against the attitude rows (item 5, measured
2026-11-25, stop 46)".
"""

import argparse
import sys
from pathlib import Path

import numpy as np

from fahv.campaign import store
from fahv.campaign.draws import _vehicle, draw, overrides
from fahv.design.artefacts import load_design
from fahv.loop.simulate import simulate
from fahv.runs.metrics import metrics

TRACE_TIMES = (0, 5, 10, 20, 30, 40, 50, 60, 70, 80, 99)


def run_once(design, data: dict, index: int, rows, duration: float):
    """Simulate run ``index`` with attitude rows ``rows`` (2,) [deg] (None: the design's)."""
    variant = data["variants"][0]
    ov = overrides(draw(data, design.case, index), design, variant)
    if rows is not None:
        ov.setdefault("nominal_trajectory", {})["mpc.att_max"] = [float(r) for r in rows]
    return simulate(design, variant, duration, overrides=ov)


def trace(run) -> None:
    """Print the transient of one run at :data:`TRACE_TIMES`."""
    for tt in TRACE_TIMES:
        k = min(int(np.searchsorted(run.t, tt)), run.t.size - 1)
        x, xr, u = run.x[k], run.x_r[k], run.u[k]
        print(
            f"  t {run.t[k]:5.1f} s  h - h_c {x[0] - run.h_c[k]:7.1f} ft  V - V_c "
            f"{x[1] - run.V_c[k]:7.1f} ft/s  set point {run.h_g[k] - run.h_c[k]:6.1f} ft "
            f"{run.V_g[k] - run.V_c[k]:6.1f} ft/s  alpha {np.degrees(x[2] - xr[2]):+.3f} "
            f"theta {np.degrees(x[3] - xr[3]):+.3f} gamma {np.degrees(x[3] - x[2]):+.3f} deg  "
            f"Phi {u[0]:.3f} delta_e {np.degrees(u[1]):.2f} deg"
        )


def main(argv=None) -> int:
    """Command line (module docstring); returns the exit status (2: not a campaign folder)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("rows", nargs="*", type=float, default=[0.36, 0.37, 0.38, 0.39, 0.40])
    ap.add_argument("--theta", action="store_true", help="widen the theta row only")
    ap.add_argument("--trace", type=int, default=None, help="one run's transient")
    a = ap.parse_args(argv)
    man = store.read_manifest(a.campaign)
    if man is None:
        print(f"{a.campaign}: not a campaign folder", file=sys.stderr)
        return 2
    data = man["campaign"]
    design = load_design(a.campaign / "design")
    veh = _vehicle(design.summary.get("provenance", {}).get("vehicle_file", ""))
    limit = float(data["requirements"]["settling_s"])
    duration = float(man["duration"])
    base = [float(v) for v in np.degrees(design.arrays["att_max"])]
    print(f"design rows alpha / theta {base[0]:.3f} / {base[1]:.3f} deg")
    if a.trace is not None:
        for rows in [None, *a.rows]:
            w = base if rows is None else ([base[0], rows] if a.theta else [rows, rows])
            print(f"run {a.trace}, rows {w[0]:.3f} / {w[1]:.3f} deg:")
            trace(run_once(design, data, a.trace, w, min(duration, 100.0)))
        return 0
    late = sorted(
        r["index"] for r in store.read_rows(a.campaign)
        if not max(r["settling_time_h_s"], r["settling_time_V_s"]) <= limit
    )  # fmt: skip
    print(f"{len(late)} runs settle after {limit:.0f} s: {late}")
    for rows in a.rows:
        w = [base[0], rows] if a.theta else [rows, rows]
        ts = []
        for i in late:
            m = metrics(run_once(design, data, i, w, duration), veh.limits)
            ts.append(max(m["settling_time_h_s"], m["settling_time_V_s"]))
        ts = np.array(ts)
        print(
            f"rows {w[0]:.3f} / {w[1]:.3f} deg: {int(np.sum(~(ts <= limit)))} / {len(late)} "
            f"still after {limit:.0f} s, settling max {np.nanmax(ts):.1f} s, median "
            f"{np.nanmedian(ts):.1f} s",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
