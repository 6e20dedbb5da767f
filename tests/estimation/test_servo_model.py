"""The servos' discrete model of the Kalman filter's gains (fahv.estimation.servo_model)
against the plant's own kernel integrating the same servos."""

import numpy as np

from fahv.estimation.servo_model import servo_step, with_servos
from fahv.model.actuators import kernel_parameters
from fahv.model.vehicle import load_vehicle
from fahv.plant.rk4 import params_records, rk4_cm_act

TS = 0.02


def test_the_discrete_servos_are_the_kernels_without_limits():
    """From random servo states and commands (rate limits lifted), the kernel's servo
    states after Ts (RK4, 400 substeps) equal Phi_s s + Gamma_s u, and the average of its
    positions over the step (trapezoid over the 400 substeps) equals P_s s + P_u u, to
    1e-6 of the servo's scale."""
    veh = load_vehicle()
    AP = kernel_parameters(veh.actuators["second_order"], veh.limits.u_min, veh.limits.u_max)
    AP[:, 2:4] = np.inf
    AP[:, 4], AP[:, 5] = -1e9, 1e9  # no position limit either: the linear servo
    Phi, Gam, Ps, Pu = servo_step(AP, TS)
    rng = np.random.default_rng(2)
    rec = params_records([veh.params])
    x = np.zeros((1, 9))
    x[0, :4] = [85500.0, 7900.0, 0.02, 0.02]
    n = 400
    for _ in range(5):
        s = rng.normal(size=4) * [0.1, 1.0, 0.05, 5.0]
        u = rng.normal(size=2) * [0.1, 0.05]
        a, pos = s[None].copy(), [s[::2].copy()]
        for _ in range(n):
            _, a, _ = rk4_cm_act(x, a, u[None], rec, AP[None], np.zeros(1, bool), TS / n, 1)
            pos.append(a[0, ::2].copy())
        pos = np.array(pos)
        avg = (pos[1:] + pos[:-1]).sum(axis=0) / (2 * n)
        np.testing.assert_allclose(a[0], Phi @ s + Gam @ u, atol=1e-6 * 5.0)
        np.testing.assert_allclose(avg, Ps @ s + Pu @ u, atol=1e-6)


def test_the_augmented_vertices_hold_a_trim_with_the_servos_at_rest():
    """x, d = 0 and the servos at rest at the command u: the augmented model (its matrix,
    plus the command's input [B_i P_u; 0; Gamma_s]) moves x by B_i u, as the ZOH model
    does, and the servos stay; d enters as the command does."""
    veh = load_vehicle()
    AP = kernel_parameters(veh.actuators["second_order"], veh.limits.u_min, veh.limits.u_max)
    rng = np.random.default_rng(3)
    A, B = rng.normal(size=(3, 9, 9)) * 0.1, rng.normal(size=(3, 9, 2))
    Az = with_servos(A, B, AP, TS)
    assert Az.shape == (3, 15, 15)
    u = np.array([0.3, 0.2])
    z = np.concatenate([np.zeros(9), np.zeros(2), [u[0], 0.0, u[1], 0.0]])
    _, Gam, _, Pu = servo_step(AP, TS)
    for i in range(3):
        Bz = np.vstack([B[i] @ Pu, np.zeros((2, 2)), Gam])
        nxt = Az[i] @ z + Bz @ u
        np.testing.assert_allclose(nxt[:9], B[i] @ u, atol=1e-12)
        np.testing.assert_allclose(nxt[11:], z[11:], atol=1e-12)
        rows = np.r_[0:9, 11:15]  # d's columns outside d's own rows: the command's
        np.testing.assert_allclose(Az[i][rows, 9:11], Bz[rows], atol=0)
