"""The law ``tube_mpc`` forms its error's q through the notch: e'_q = notch(q - q_r - q_n)
(case key ``tube.filter_nominal_q``; without it the paper's q' - q_r - q_n).

The notch_filter node filters the measured q; the law filters the nominal's q with a
replica of the same filter, so that the error is the one the notch certificate covers
(fahv.tube.notch_loop.notch_tube). Checked against the filter run on the difference,
with B = 3 runs of random pitch rates.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from fahv.control.tube_mpc import TubeMPCLaw
from fahv.model.notch import DiscreteNotch, NotchFilter
from fahv.model.vehicle import IQ

NOTCH = {"omega_z": 19.05, "eps_z": 0.02, "omega_p": 19.05, "eps_p": 0.1}
TS, B, STEPS = 0.02, 3, 400


def _params(enabled: bool, filtered: bool = True) -> dict:
    rng = np.random.default_rng(1)
    return {
        "Ts": TS, "law": "tube_mpc", "design_model": "cm", "tau": 1.0,
        "F": rng.normal(size=(2, 9)), "N": np.diag(rng.uniform(0.5, 2.0, 9)),
        "notch.enabled": enabled, **{f"notch.{k}": v for k, v in NOTCH.items()},
        "filter_nominal_q": filtered,
    }  # fmt: skip


def _errors(enabled: bool, filtered: bool = True):
    """Errors of the law and the expected ones, over STEPS steps: the filter on
    q - q_r - q_n (``filtered``) or q' - q_r - q_n (the paper's error)."""
    rng = np.random.default_rng(2)
    law = TubeMPCLaw(_params(enabled, filtered), n_runs=B)
    nf = NotchFilter(*NOTCH.values())
    measured, difference = DiscreteNotch(nf, TS, np.zeros(B)), DiscreteNotch(nf, TS, np.zeros(B))
    out = []
    for k in range(STEPS):
        x = rng.normal(size=(B, 9))
        x_r, x_n = rng.normal(size=(B, 9)), rng.normal(size=(B, 9))
        q = x[:, IQ].copy()
        if enabled:
            x[:, IQ] = measured.step(q)  # the notch_filter node's q'
        ref = SimpleNamespace(x_r=x_r, x_n=x_n, u_r=np.zeros((B, 2)), u_n=np.zeros((B, 2)))
        step = law.step(k, x, ref, None)
        want = x - x_r - x_n  # q' (q without the notch) less the raw nominal q: the paper's
        if enabled and filtered:
            want[:, IQ] = difference.step(q - x_r[:, IQ] - x_n[:, IQ])
        out.append((step.e, want))
    return out


@pytest.mark.parametrize("enabled, filtered", [(True, True), (False, True), (True, False)])
def test_the_error_is_the_filtered_difference(enabled, filtered):
    for e, want in _errors(enabled, filtered):
        np.testing.assert_allclose(e, want, rtol=0.0, atol=1e-12)


def test_without_the_replica_the_error_would_differ():
    """The replica matters: the filtered q less the raw nominal q is off by O(1)."""
    rng = np.random.default_rng(3)
    nf = NotchFilter(*NOTCH.values())
    a, b = DiscreteNotch(nf, TS, np.zeros(1)), DiscreteNotch(nf, TS, np.zeros(1))
    worst = 0.0
    for _ in range(STEPS):
        q, qn = rng.normal(size=1), rng.normal(size=1)
        worst = max(worst, float(np.abs((a.step(q) - qn) - b.step(q - qn)).max()))
    assert worst > 0.1


def test_the_adjustable_law_feeds_tau_F_e_back_and_measures_the_level_in_Z():
    """Eq. (54) on a nine-state design: u = u_r + u_n + tau F e with tau = 0.8, and the
    level e' N^-1 e, the set the design certifies for the whole W (the paper's tau Z
    holds only for W' of eq. 47); a tau outside (0, 1] is refused."""
    rng = np.random.default_rng(4)
    p = {**_params(False), "tau": 0.8}
    law = TubeMPCLaw(p, n_runs=B)
    for k in range(5):
        x, x_r, x_n = (rng.normal(size=(B, 9)) for _ in range(3))
        u_r, u_n = rng.normal(size=(B, 2)), rng.normal(size=(B, 2))
        ref = SimpleNamespace(x_r=x_r, x_n=x_n, u_r=u_r, u_n=u_n)
        step = law.step(k, x, ref, None)
        e = x - x_r - x_n
        np.testing.assert_allclose(step.u, u_r + u_n + e @ (0.8 * p["F"]).T, rtol=1e-12)
        want = np.einsum("bi,ij,bj->b", e, np.linalg.inv(p["N"]), e)
        np.testing.assert_allclose(step.level, want, rtol=1e-12)
    with pytest.raises(ValueError, match="tau must be in"):
        TubeMPCLaw({**p, "tau": 0.0}, n_runs=B)
