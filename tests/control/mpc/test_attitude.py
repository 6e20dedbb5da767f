"""Attitude rows of the nominal QP from the tube's support (fahv.control.mpc.attitude)."""

import numpy as np
import pytest

from fahv.control.mpc.attitude import attitude_bounds
from fahv.errors import DesignError


def test_attitude_bounds_follow_from_the_tube_support():
    N = np.diag(np.r_[1.0, 1.0, np.radians([0.1, 0.2]) ** 2, np.ones(5)])
    att = attitude_bounds(N)
    np.testing.assert_allclose(np.degrees(att.support), [0.1, 0.2])
    np.testing.assert_allclose(np.degrees(att.used), [0.4, 0.3])
    assert att.is_certified and not att.given
    att = attitude_bounds(N, 0.35)  # a given bound beyond the certified one
    assert att.given and not att.is_certified and "NOT certified" in att.report()
    # rows within the requirement but narrower than a box corner's own trim: the QP
    # widens them to that trim, so the certificate does not hold (0.45 deg reached)
    att = attitude_bounds(N, 0.25, np.radians(0.35))
    assert not att.is_certified
    assert "trim offset exceeds the rows" in att.report() and "0.450 / 0.550 deg" in att.report()
    assert attitude_bounds(N, 0.3, np.radians(0.3)).is_certified  # rows hold the trim
    with pytest.raises(DesignError, match="leaves no nominal bound"):
        attitude_bounds(np.diag(np.r_[1.0, 1.0, np.radians([0.6, 0.2]) ** 2, np.ones(5)]))
