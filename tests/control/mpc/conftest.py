"""Fixtures of the nominal MPC's tests: one run's tracking QP on the test design."""

import numpy as np
import pytest

from fahv.control.mpc.settings import MPCSettings
from fahv.control.mpc.tracking import TrackingMPC
from fahv.model.lpv import PolytopicLPV
from fahv.model.trim import TrimMap


@pytest.fixture
def make_mpc(design):
    """Factory of :class:`TrackingMPC` on the test design: ``make_mpc(**changes)`` with
    the Case 1 horizon and weights, ``changes`` replacing :class:`MPCSettings` fields."""

    def make(**changes):
        a = design.arrays
        lpv = PolytopicLPV(a["A"], a["B"], a["h_grid"], a["V_grid"], a["W_h"], a["W_V"])
        tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
        s = dict(
            M=25, N_p=30, q_w=np.array([1, 1, 0.1, 0.1, 0.01, 0, 0, 0, 0.0]), r_w=np.ones(2),
            t_w=np.array([1e4, 1e4]), dtheta_max=np.array([300.0, 150.0]),
            reschedule=np.array([100.0, 50.0]), att_max=np.radians(0.3),
        )  # fmt: skip
        s.update(changes)
        return TrackingMPC(
            lpv, tm, a["K"], a["Q"], a["u_lo"], a["u_hi"], a["Dx"], a["Du"], MPCSettings(**s)
        )

    return make
