"""The lines the tube's computations print while they run: formatting only.

The closure of the eight-state tube set prints one line per W_8-Z_8 iteration
(`closure_iteration_line`) and every tube loop through a notch prints its verdict
(`notch_loop_line`) as it is found, from the processes that compute them. Both
format a result computed elsewhere and import nothing of the computations; the lines of
the certificate a design prints are `fahv.certificate.report`.
"""

from __future__ import annotations

import numpy as np


def join(values, fmt: str, sep: str = " ") -> str:
    """`values` formatted with `fmt` and joined with `sep`."""
    return sep.join(format(v, fmt) for v in values)


def closure_iteration_line(it: int, tightening, N_8, ab, ratio) -> str:
    """The design log's line of one W_8-Z_8 iteration (`fahv.tube.closure`).

    Parameters
    ----------
    it : int
        The iteration's index.
    tightening : (2,) array_like
        F_8 Z_8's support per input [-, rad].
    N_8 : (8, 8) ndarray
        Z_8's shape.
    ab : fahv.bounds.one_step_bound.AltitudeBound
    ratio : (8,) array_like
        bound / W_8 per row.
    """
    return (
        f"eight-state tube, iteration {it}: tightening {tightening[0]:.4f} / "
        f"{np.degrees(tightening[1]):.3f} deg, alpha support "
        f"{np.degrees(np.sqrt(N_8[1, 1])):.4f} deg, H = {ab.H:.2f} ft (step {ab.step:.3f} "
        f"ft, w_h {ab.w_h:.3f} ft); bound / W_8 (V ... eta_2_dot) " + join(ratio, ".3f")
    )



def notch_loop_line(loop) -> str:
    """The design log's line of a tube loop through a notch, with its verdict.

    Parameters
    ----------
    loop : fahv.tube.notch_loop.NotchLoop
    """
    head = (
        f"variant {loop.variant}: tube feedback through the notch on q (omega {loop.omega:.2f} "
        f"rad/s, eps_p {loop.eps_p:g}): largest spectral radius over the vertices "
        f"{loop.rho:.6f} (on the measured q {loop.rho_q:.6f})"
    )
    if not loop.stable:
        return head + f": UNSTABLE at vertex {loop.vertex}: NOT certified with the notch"
    if loop.s is None:
        return head + (
            ": stable at every vertex (necessary only); the RPI certificate is for the "
            "feedback on the measured q: NOT certified with the notch"
        )
    if not np.isfinite(loop.s):
        return head + (
            "; no ellipsoid of the loop with the filter's states RPI for W with its input "
            "support within the tightening (LMI infeasible): NOT certified with the notch"
        )
    closed = ""
    if loop.w_ratio is not None:
        closed = (f", over the loop's own set of (e, u - v): H / the tube set's "
                  f"{loop.w_ratio[0]:.3f}, W's bound / W per row "
                  + join(loop.w_ratio[1:], ".3f"))  # fmt: skip
    return head + (
        ("; with the gain designed for the loop" if loop.designed else "")
        + f"; an ellipsoid of the loop with the filter's states, RPI for W: exact worst "
        f"one-step level {loop.level:.6f}, its projection on e inside {loop.s:.4f} x Z, "
        f"input support through q' {join(loop.supports, '.4f', ' / ')} (tightening "
        f"{join(loop.tightening, '.4f', ' / ')}){closed}"
        + (": certified with the notch  OK" if loop.certified
           else ": NOT certified with the notch")
    )  # fmt: skip
