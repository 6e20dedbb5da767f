"""The Kothare RMPC baseline: its first solve on the Case 1 step is certified, an
uncertifiable state is refused, and a later failure keeps the certified gain."""

from types import SimpleNamespace

import numpy as np
import pytest

from fahv.control.rmpc import RobustMPC
from fahv.errors import DesignError
from fahv.loop.cores import build_core
from fahv.loop.params import node_parameters, validate
from fahv.synthesis.lmi import scale_vertices
from fahv.synthesis.nominal import contraction


@pytest.fixture(scope="module")
def setup(design):
    p = node_parameters(design, "rmpc")
    r = validate("rmpc", p["rmpc"])
    rmpc = RobustMPC(
        r["rmpc_A"], r["rmpc_B"], r["u_room"], r["psi"], r["sigma"], r["Dx"], r["Du"], 250
    )
    state = build_core("plant", p["plant"]).state()
    nom = build_core("nominal_trajectory", p["nominal_trajectory"]).on_state(state)
    ref = SimpleNamespace(x_r=nom.x_r[0], u_r=nom.u_r[0])
    return rmpc, r, state.x()[0], ref


def test_first_solve_on_the_case1_step_is_certified(setup):
    rmpc, r, x, ref = setup
    u = rmpc.step(0, x, ref.x_r, ref.u_r)
    assert rmpc.have_gain and rmpc.n_solves == 1 and rmpc.n_failed == 0
    # re-check the certificate independently of the controller's own check
    Dx, Du = np.asarray(r["Dx"]), np.asarray(r["Du"])
    As, Bs = scale_vertices(np.asarray(r["rmpc_A"]), np.asarray(r["rmpc_B"]), Dx, Du)
    Ks = rmpc.K * Dx[None, :] / Du[:, None]
    Q = rmpc.Q_s
    assert contraction(As, Bs, Ks, Q) < 1.0
    x0 = (x - ref.x_r) / Dx
    assert x0 @ np.linalg.solve(Q, x0) <= 1.0 + 1e-6  # the state is inside E(Q)
    room = np.asarray(r["u_room"]) / Du
    assert np.all(np.sqrt(np.einsum("ij,jk,ik->i", Ks, Q, Ks)) <= room * (1 + 1e-6))
    np.testing.assert_allclose(u, ref.u_r + rmpc.K @ (x - ref.x_r), rtol=0, atol=0)
    assert np.all(np.abs(u - ref.u_r) <= np.asarray(r["u_room"]) * (1 + 1e-6))


def test_an_uncertifiable_later_state_keeps_the_previous_gain(setup):
    rmpc, r, x, ref = setup
    if not rmpc.have_gain:
        rmpc.step(0, x, ref.x_r, ref.u_r)
    K, failed = rmpc.K.copy(), rmpc.n_failed
    far = ref.x_r + 40.0 * (x - ref.x_r)  # 40 times the step: no ellipsoid fits
    rmpc.step(250, far, ref.x_r, ref.u_r)
    assert rmpc.n_failed == failed + 1
    np.testing.assert_array_equal(rmpc.K, K)


def test_a_first_solve_that_cannot_be_certified_stops_the_run(setup):
    _, r, x, ref = setup
    fresh = RobustMPC(
        r["rmpc_A"], r["rmpc_B"], r["u_room"], r["psi"], r["sigma"], r["Dx"], r["Du"], 250
    )
    with pytest.raises(DesignError, match="first LMI solve"):
        fresh.step(0, ref.x_r + 40.0 * (x - ref.x_r), ref.x_r, ref.u_r)
    assert fresh.n_failed == 1 and not fresh.have_gain
