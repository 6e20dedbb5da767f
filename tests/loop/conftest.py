"""Checks shared by the loop tests: a run's measured figures against the documented ones."""

import numpy as np
import pytest


def check_figures(m: dict, settling: tuple, attitude: tuple, atol_s: float = 0.5,
                  atol_deg: float = 0.01) -> None:  # fmt: skip
    """Assert a run's settling times h / V [s] within atol_s and its largest alpha / theta
    errors [deg] within atol_deg of the figures the docs give (`fahv simulate`'s metrics
    `m`), and no command beyond the input limits."""
    np.testing.assert_allclose([m["settling_time_h_s"], m["settling_time_V_s"]], settling,
                               atol=atol_s)  # fmt: skip
    np.testing.assert_allclose([m["alpha_err_max_deg"], m["theta_err_max_deg"]], attitude,
                               atol=atol_deg)  # fmt: skip
    assert m["input_limit_violations"] == 0


@pytest.fixture
def figures():
    """`check_figures`: a run's settling times and attitude against the documented ones."""
    return check_figures
