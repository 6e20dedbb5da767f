"""The ECM's CM part (fahv.model.cascade): what a filter of the airframe runs on in Case 2."""

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from fahv.model.cascade import airframe_arrays, cascade_transform, cm_vertices
from fahv.model.lpv import PolytopicLPV
from fahv.model.notch import NotchFilter
from fahv.spec.store import stored_design

DESIGNS = Path(__file__).resolve().parents[2] / "offline_design" / "designs"


@pytest.fixture(scope="module")
def ecm():
    """The shipped ECM design of Case 2 and its notch."""
    d = stored_design(DESIGNS / "ecm_paper.yaml")[1]
    n = d.case["notch"]
    return d, NotchFilter(n["omega_z"], n["eps_z"], n["omega_p"], n["eps_p"])


def test_the_ecm_design_holds_the_cm_of_the_cm_design(ecm):
    """The CM part of ecm_paper's 6 vertices, scheduled, is cm_paper's 20-vertex model:
    two TP models of the same CM over the same envelope. Measured: at most 4.1e-5 in A and
    6.0e-5 in B, scaled by D_x and D_u (entries up to 11.8 and 0.77). The ECM's first
    nine rows and columns read without the change of coordinates differ by 0.30 at the
    design point (measured; asserted above 0.1): the change is what makes them the CM."""
    d, _ = ecm
    a = airframe_arrays(d.arrays, "ecm", d.case["notch"])
    c = stored_design(DESIGNS / "cm_paper.yaml")[1].arrays
    grid = ("h_grid", "V_grid", "W_h", "W_V")
    ours = PolytopicLPV(a["A"], a["B"], *(a[k] for k in grid))
    theirs = PolytopicLPV(c["A"], c["B"], *(c[k] for k in grid))
    Dx, Du = np.asarray(c["Dx"]), np.asarray(c["Du"])
    assert np.array_equal(a["Dx"], Dx)
    for h, V in [(85500.0, 7900.0), (86100.0, 8150.0), (85000.0, 7700.0), (86500.0, 8300.0)]:
        (A1, B1), (A2, B2) = ours.system(h, V), theirs.system(h, V)
        assert np.abs((A1 - A2) * Dx[None] / Dx[:, None]).max() < 1e-4
        assert np.abs((B1 - B2) * Du[None] / Dx[:, None]).max() < 1e-4
    raw = PolytopicLPV(np.asarray(d.arrays["A"])[:, :9, :9], np.asarray(d.arrays["B"])[:, :9],
                       *(a[k] for k in grid))  # fmt: skip
    A_raw, A_cm = raw.system(85500.0, 7900.0)[0], theirs.system(85500.0, 7900.0)[0]
    assert np.abs((A_raw - A_cm) * Dx[None] / Dx[:, None]).max() > 0.1


def test_the_filter_block_is_the_sampled_notch(ecm):
    """In cascade coordinates every vertex's filter block is exp(A_q Ts) to 1e-12 (of
    entries up to 5.9): the ECM is the CM in series with the notch, eq. (39)-(43)."""
    d, nf = ecm
    T = cascade_transform(nf)
    A_q = nf.ss()[0]
    blocks = np.linalg.inv(T) @ np.asarray(d.arrays["A"]) @ T
    expected = scipy.linalg.expm(A_q * d.case["Ts"])
    assert np.abs(blocks[:, 9:, 9:] - expected).max() < 1e-12


def test_a_model_that_is_not_the_cascade_is_refused(ecm):
    """Read with another notch, the filter's states act on the airframe: a named error."""
    d, _ = ecm
    other = NotchFilter(19.05, 0.02, 19.05, 0.1)
    with pytest.raises(ValueError, match=r"vertex 0 of the ECM is not the CM in series"):
        cm_vertices(d.arrays["A"], d.arrays["B"], other)
    with pytest.raises(ValueError, match=r"ECM vertices must be A \(R, 11, 11\)"):
        cm_vertices(np.zeros((2, 9, 9)), np.zeros((2, 9, 2)), other)
    with pytest.raises(ValueError, match="design_model 'dm'"):
        airframe_arrays(d.arrays, "dm", d.case["notch"])


def test_a_cm_design_passes_as_it_is():
    c = stored_design(DESIGNS / "cm_certified.yaml")[1]
    a = airframe_arrays(c.arrays, "cm", c.case["notch"])
    assert all(np.array_equal(a[k], np.asarray(c.arrays[k], float)) for k in a)
