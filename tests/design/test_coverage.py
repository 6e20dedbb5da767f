"""Coverage of an elevator loss over the whole parameter box (fahv.bounds.coverage)."""

import numpy as np
import pytest

from fahv.bounds.coverage import TRIM_FREE_PARAMETERS, corner_trims, loss_coverage
from fahv.plant.uncertainty import PAPER_UNCERTAINTY


@pytest.fixture(scope="module")
def trims(vehicle):
    from fahv.model.trim import trim_map

    return trim_map(vehicle, 13, 13, "cm")


def _perturbed(vehicle, signs):
    import dataclasses

    from fahv.plant.uncertainty import perturb

    return dataclasses.replace(vehicle, params=perturb(vehicle.params, PAPER_UNCERTAINTY, signs))


def test_vectorised_trim_equals_the_scalar_trim_and_ignores_I_yy(vehicle):
    """trim_batch against fahv.model.trim.trim on interior draws; I_yy does not enter a trim."""
    import dataclasses

    from fahv.model.trim import trim, trim_batch

    rng = np.random.default_rng(3)
    names = list(PAPER_UNCERTAINTY)
    draws = rng.uniform(-1.0, 1.0, (6, len(names)))
    pts = [(85000.0, 7700.0), (85750.0, 8000.0), (86500.0, 8300.0)]
    for s in draws:
        veh = _perturbed(vehicle, dict(zip(names, s, strict=True)))
        h = np.array([p[0] for p in pts])
        V = np.array([p[1] for p in pts])
        z, res = trim_batch(veh.params, h, V, np.tile([[0.03], [0.22], [0.27]], (1, 3)))
        assert np.all(res < 1e-10)
        for i, (hh, vv) in enumerate(pts):
            tp = trim(veh, hh, vv)
            np.testing.assert_allclose(z[:, i], [tp.alpha, tp.delta_e, tp.Phi], atol=1e-11)
        # I_yy +/- 10 %: the same trim to the last bits the Newton iteration leaves
        for f in (0.9, 1.1):
            p2 = dataclasses.replace(veh.params, I_yy=veh.params.I_yy * f)
            z2, _ = trim_batch(p2, h, V, np.tile([[0.03], [0.22], [0.27]], (1, 3)))
            np.testing.assert_allclose(z2, z, atol=1e-13)


def test_loss_coverage_reproduces_the_measured_figures(vehicle, trims):
    """Tightened elevator 18.24 deg (the rho_min = 0.7 design): 22.8 % over the envelope,
    27.9 % at the Case 1 end point, worst corner heavy with the weaker c_e at (86500, 7700)."""
    u_lo = np.array([0.178, np.radians(-18.24)])
    u_hi = np.array([1.322, np.radians(18.24)])
    cov = loss_coverage(vehicle, PAPER_UNCERTAINTY, trims, u_lo, u_hi, path=[(86100.0, 8150.0)])
    assert cov.corners == 512 and cov.points == 169
    assert 100 * cov.loss == pytest.approx(22.8, abs=0.05)
    assert 100 * cov.loss_path == pytest.approx(27.9, abs=0.05)
    assert cov.worst_corner["m"] == 1.0 and cov.worst_corner["c_e"] == -1.0
    assert cov.worst_corner["I_yy"] == 0.0
    assert cov.worst_point == (86500.0, 7700.0)
    assert np.degrees(cov.delta_e_max) == pytest.approx(14.072, abs=1e-3)
    assert cov.monotone == (True, True)
    assert 0.0 < np.degrees(cov.remainder) < 0.01
    # the trim attitude offset of the box from the nominal trim (what the nominal MPC holds)
    assert np.degrees(cov.alpha_offset_max) == pytest.approx(0.348, abs=1e-3)
    msg = cov.failing(0.7, u_hi[1])
    assert "m +" in msg and "c_e -" in msg and "h = 86500 ft, V = 7700.0 ft/s" in msg
    assert "20.10" in msg and "22.8 %" in msg
    assert cov.failing(0.78, u_hi[1]) == ""


def test_loss_coverage_worst_case_is_a_corner_and_the_grid_remainder_holds(vehicle, trims):
    """Interior draws never need more elevator than the worst corner at the same point, and a
    grid three times finer stays within the grid maximum plus the stated remainder."""
    from fahv.model.trim import TrimMap, trim_batch

    u_lo = np.array([0.178, np.radians(-18.24)])
    u_hi = np.array([1.322, np.radians(18.24)])
    cov = loss_coverage(vehicle, PAPER_UNCERTAINTY, trims, u_lo, u_hi)
    names = [k for k in PAPER_UNCERTAINTY if k not in TRIM_FREE_PARAMETERS]
    _, corners, z = corner_trims(vehicle, PAPER_UNCERTAINTY, trims)
    de_corner_max = z[1].max(axis=0)  # (N_h, N_V)
    # 2000 interior draws at every 4th grid point
    rng = np.random.default_rng(11)
    s = rng.uniform(-1.0, 1.0, (2000, len(names)))
    ih, iv = np.meshgrid(np.arange(0, 13, 4), np.arange(0, 13, 4), indexing="ij")
    ih, iv = ih.ravel(), iv.ravel()
    P = ih.size
    vp = vehicle.params.replace(
        **{k: np.repeat(getattr(vehicle.params, k) * (1 + s[:, j] * PAPER_UNCERTAINTY[k]), P)
           for j, k in enumerate(names)}
    )  # fmt: skip
    h = np.tile(trims.h_grid[ih], 2000)
    V = np.tile(trims.V_grid[iv], 2000)
    g = np.stack([trims.x_r[ih, iv, 2], trims.u_r[ih, iv, 1], trims.u_r[ih, iv, 0]])
    zi, res = trim_batch(vp, h, V, np.tile(g, (1, 2000)))
    assert np.all(res < 1e-8)
    de_i = zi[1].reshape(2000, P)
    assert np.all(de_i <= de_corner_max[ih, iv][None, :] + 1e-12)
    # the eight corners that need the most elevator, on a 37 x 37 grid
    top = np.argsort(z[1].max(axis=(1, 2)))[-8:]
    signs = corners[top]
    hf = np.linspace(trims.h_grid[0], trims.h_grid[-1], 37)
    Vf = np.linspace(trims.V_grid[0], trims.V_grid[-1], 37)
    xf, uf = trims.at(*[a.ravel() for a in np.meshgrid(hf, Vf, indexing="ij")])
    fine = TrimMap(hf, Vf, xf.reshape(37, 37, -1), uf.reshape(37, 37, 2))
    _, _, zf = corner_trims(vehicle, PAPER_UNCERTAINTY, fine, signs)
    assert zf[1].max() <= cov.delta_e_max + cov.remainder
    assert zf[1].max() == pytest.approx(cov.delta_e_max, abs=1e-9)  # monotone: a corner
