"""Trim against the numbers of the vehicle data (Parker 2007 rigid curve fit)."""

import numpy as np
import pytest

from fahv.errors import EnvelopeError, TrimError
from fahv.model.trim import TRIM_TOL, trim, trim_grid


@pytest.mark.parametrize("model", ["dm", "cm"])
@pytest.mark.parametrize(
    ("h", "V", "alpha_deg", "de_deg", "Phi"),
    [(85000.0, 7702.08, 1.644, 12.54, 0.2681), (85500.0, 7900.0, 1.577, 12.38, 0.2696)],
)
def test_trim_matches_published_rigid_trim(vehicle, model, h, V, alpha_deg, de_deg, Phi):
    tp = trim(vehicle, h, V, model)
    # tolerances: 0.01 deg, 0.05 deg, 0.002
    assert np.degrees(tp.alpha) == pytest.approx(alpha_deg, abs=0.01)
    assert np.degrees(tp.delta_e) == pytest.approx(de_deg, abs=0.05)
    assert tp.Phi == pytest.approx(Phi, abs=0.002)
    assert tp.residual < TRIM_TOL
    # level flight: theta = alpha, q = 0, flexible coordinates at rest and non-zero
    assert tp.x_r[3] == tp.x_r[2] and tp.x_r[4] == 0.0
    assert abs(tp.eta_1) > 0.1 and abs(tp.eta_2) > 0.1


def test_cm_and_dm_trim_agree(vehicle):
    a, b = trim(vehicle, 86000.0, 8100.0, "dm"), trim(vehicle, 86000.0, 8100.0, "cm")
    np.testing.assert_allclose(a.x_r, b.x_r, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(a.u_r, b.u_r, rtol=1e-12, atol=1e-12)


def test_trim_grid_covers_envelope(vehicle):
    env = vehicle.envelope
    rows = trim_grid(
        vehicle, np.linspace(env.h_min, env.h_max, 3), np.linspace(env.V_min, env.V_max, 4)
    )
    assert len(rows) == 3 and len(rows[0]) == 4
    assert max(tp.residual for row in rows for tp in row) < TRIM_TOL
    # faster flight needs less elevator and less angle of attack
    assert rows[0][-1].alpha < rows[0][0].alpha


ENVELOPE_MSG = r"h in \[85000.0, 86500.0\] ft, V in \[7700.0, 8300.0\]"


@pytest.mark.parametrize(("h", "V"), [(90000.0, 7900.0), (85500.0, 7000.0), (float("nan"), 7.9e3)])
def test_outside_envelope_names_envelope(vehicle, h, V):
    with pytest.raises(EnvelopeError, match=ENVELOPE_MSG):
        trim(vehicle, h, V)


def test_no_trim_within_input_limits(vehicle):
    # shrink the elevator range below the ~12.4 deg that trim needs
    import dataclasses

    small = dataclasses.replace(
        vehicle,
        limits=dataclasses.replace(
            vehicle.limits, delta_e_min=-np.radians(5), delta_e_max=np.radians(5)
        ),
    )
    with pytest.raises(TrimError, match="delta_e"):
        trim(small, 85500.0, 7900.0)
