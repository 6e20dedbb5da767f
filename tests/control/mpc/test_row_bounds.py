"""The tracking QP's vectors of a batch: each run's as alone, bit for bit."""

import numpy as np

from fahv.control.mpc.row_bounds import QPVectors
from fahv.control.mpc.settings import input_box, range_box, rate_limits, state_box


def _rows_of_every_kind(make_mpc):
    """An MPC with the range, own-trim, rate and input-box rows."""
    return make_mpc(
        hv_box=range_box([84000.0, 86000.0, 7700.0, 8300.0]),
        x_box=state_box([-0.2, -1.0, -0.3, -5.0, -50.0, -5.0, -50.0,
                         0.25, 1.0, 0.3, 5.0, 50.0, 5.0, 50.0]),
        du_max=rate_limits([0.02, 0.2]),
        u_box=input_box([-0.12, 0.05, -1.0, 7.0]),
    )  # fmt: skip


def test_a_batchs_vectors_are_each_runs_own_bit_for_bit(design, make_mpc):
    """Three runs scheduled at three (h, V), each with its own z0, u_base, command, x_d
    and input before: the stacked vectors equal each run's batch of one with
    `array_equal`, for the QP and both recovery QPs, with and without the rate row's start;
    and the rows have the length of the constraint matrix."""
    rng = np.random.default_rng(7)
    c = design.case["command"]
    points = [(c["h0"], c["V0"]), (c["h0"] + 300.0, c["V0"] + 40.0), (c["h0"] - 200.0, c["V0"])]
    mpcs = [_rows_of_every_kind(make_mpc) for _ in points]
    for mpc, (h, V) in zip(mpcs, points, strict=True):
        mpc.schedule(h, V)
    n, B = mpcs[0].n, len(mpcs)
    batch = QPVectors(mpcs[0], B)
    for b, mpc in enumerate(mpcs):
        batch.put(b, mpc)
    z0 = rng.normal(size=(B, n)) * np.array([20.0, 5.0, 1e-3, 1e-3, 1e-3, 1e-2, 1e-2, 1e-2, 1e-2])
    u_base = np.array([m.u_r_s for m in mpcs]) + rng.normal(size=(B, 2)) * [0.01, 1e-3]
    cmd = np.array(points) + [100.0, 20.0]
    x_d = rng.normal(size=(B, n)) * 1e-4
    u_prev = u_base + rng.normal(size=(B, 2)) * [0.01, 1e-3]
    for prev in (None, u_prev):
        for recover, relax in ((False, False), (True, False), (True, True)):
            f, bl, bu = batch.compute(z0, u_base, cmd, x_d, prev, recover, relax)
            assert bl.shape == bu.shape == (B, mpcs[0].layout.ny + mpcs[0].A_c.shape[0])
            for b, mpc in enumerate(mpcs):
                one = QPVectors.of(mpc).compute(z0[b:b + 1], u_base[b:b + 1], cmd[b:b + 1],
                                          x_d[b:b + 1], None if prev is None else prev[b:b + 1],
                                          recover, relax)  # fmt: skip
                for got, want in zip((f, bl, bu), one, strict=True):
                    assert np.array_equal(got[b], want[0])
    assert not np.array_equal(f[0], f[1])  # the runs' vectors are their own
