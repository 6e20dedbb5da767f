"""The compiled TP weights (fahv.model.lpv_kernel) are numpy's, bit for bit."""

import numpy as np
import pytest

from fahv.model.lpv import PolytopicLPV


def _numpy_weights(lpv, h, V):
    """Eq. (11) in numpy: one interpolation per weighting function, then their products."""
    wh = np.stack([np.interp(h, lpv.h_grid, lpv.W_h[:, a]) for a in range(lpv.W_h.shape[1])], 1)
    wv = np.stack([np.interp(V, lpv.V_grid, lpv.W_V[:, b]) for b in range(lpv.W_V.shape[1])], 1)
    return (wh[:, :, None] * wv[:, None, :]).reshape(h.size, -1)


@pytest.fixture(scope="module")
def lpv():
    """A model with the shipped designs' grid sizes (21 x 21 samples, 4 x 5 weights)."""
    rng = np.random.default_rng(1)
    W_h, W_V = rng.random((21, 4)), rng.random((21, 5))
    W_h /= W_h.sum(1, keepdims=True)
    W_V /= W_V.sum(1, keepdims=True)
    return PolytopicLPV(rng.normal(size=(20, 3, 3)), rng.normal(size=(20, 3, 2)),
                        np.linspace(85000.0, 86500.0, 21), np.linspace(7700.0, 8300.0, 21),
                        W_h, W_V)  # fmt: skip


def test_weights_are_numpys_bit_for_bit_inside_outside_and_on_the_grid(lpv):
    rng = np.random.default_rng(0)
    h = np.concatenate([rng.uniform(83000.0, 88500.0, 20000), lpv.h_grid.repeat(21),
                        [np.nan, np.inf, -np.inf]])  # fmt: skip
    V = np.concatenate([rng.uniform(7400.0, 8600.0, 20000), np.tile(lpv.V_grid, 21),
                        [8000.0, 8000.0, 8000.0]])  # fmt: skip
    w = lpv.weights(h, V)
    assert w.shape == (h.size, 20)
    ref = _numpy_weights(lpv, h, V)
    assert np.array_equal(w, ref, equal_nan=True)
    assert np.all(np.isnan(w[-3])) and np.isfinite(w[-2]).all()  # NaN stays NaN; inf clips
    np.testing.assert_allclose(w[:-3].sum(1), 1.0, rtol=0, atol=1e-12)


def test_a_point_alone_has_the_weights_it_has_in_a_batch(lpv):
    h, V = np.array([85123.4, 86000.0, 84000.0]), np.array([7999.9, 7700.0, 9000.0])
    batch = lpv.weights(h, V)
    for b in range(3):
        assert np.array_equal(lpv.weights(h[b], V[b])[0], batch[b])


def test_mismatched_points_are_refused(lpv):
    with pytest.raises(ValueError, match=r"h \(2,\) and V \(3,\) must be"):
        lpv.weights([85000.0, 85100.0], [8000.0, 8001.0, 8002.0])
