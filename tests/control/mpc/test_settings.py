"""Settings of the nominal MPC: the rate and box parameters (fahv.control.mpc.settings)."""

import numpy as np
import pytest

from fahv.control.mpc.settings import rate_limits


def test_rate_limits_are_checked():
    assert np.all(np.isinf(rate_limits([0.0, 0.0])))
    np.testing.assert_allclose(rate_limits([0.02, 0.5]), [0.02, np.radians(0.5)])
    for bad in ([0.02, 0.0], [-0.1, 1.0], [np.nan, 1.0], [0.1]):
        with pytest.raises(ValueError, match="mpc.du_max"):
            rate_limits(bad)
