"""The loop margins: a textbook loop with known margins, the tube loop's structure, the notch."""

from __future__ import annotations

import math

import numpy as np
import pytest

import control
from fahv.analysis.margin_report import margin_table, meets
from fahv.analysis.margin_study import design_point_plant, notch_settings, vertex_plants
from fahv.analysis.margins import (
    BREAKS,
    LoopMargins,
    closed_loop,
    frequency_grid,
    loop_margins,
    loop_systems,
    open_loop,
    spectral_radius,
    worst_case,
)
from fahv.model.vehicle import IQ
from fahv.sil.workspace import ROOT
from fahv.spec.artefacts import load_design
from fahv.tube.notch_loop import notch_closed_loop

TS = 0.02
K = 10.0  # [1/s] integrator gain: k Ts / 2 = 0.1


def _margins(L, rho):
    return loop_margins(L, rho, frequency_grid(TS, (), 2000), 19.0, ("x", "y", "z"))


def test_discrete_integrator_phase_margin_crossover_and_delay_margin():
    """L(z) = k Ts / (z - 1): sin(w_c Ts / 2) = k Ts / 2 and PM = 90 deg - w_c Ts / 2."""
    L = control.ss([[1.0]], [[1.0]], [[K * TS]], 0.0, dt=TS)
    m = _margins(L, abs(1.0 - K * TS))
    w_c = 2.0 / TS * math.asin(K * TS / 2.0)  # 10.0167 rad/s
    pm = 90.0 - math.degrees(w_c * TS / 2.0)  # 84.26 deg
    assert m.stable
    assert m.w_c == pytest.approx(w_c, rel=1e-4)
    assert m.pm_deg == pytest.approx(pm, abs=0.01)
    assert m.delay_ms == pytest.approx(1e3 * math.radians(pm) / w_c, rel=1e-4)  # 146.8 ms
    assert m.gm_up_db == math.inf  # the phase reaches -180 deg only at Nyquist


def test_integrator_with_one_step_delay_gain_margin():
    """L(z) = k Ts / (z (z - 1)): phase -180 deg at w Ts = pi / 3, |L| = k Ts there."""
    L = control.ss([[1.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[K * TS, 0.0]], 0.0, dt=TS)
    m = _margins(L, spectral_radius((L.A - L.B @ L.C)[None])[0])
    w_c = 2.0 / TS * math.asin(K * TS / 2.0)
    assert m.gm_up_db == pytest.approx(20.0 * math.log10(1.0 / (K * TS)), abs=1e-3)  # 13.98 dB
    assert m.w_gm == pytest.approx(math.pi / (3.0 * TS), rel=1e-4)  # 52.36 rad/s
    assert m.pm_deg == pytest.approx(90.0 - 3.0 * math.degrees(w_c * TS / 2.0), abs=0.01)
    assert m.dm_gain_db > 0.0 and m.dm_phase_deg > 0.0


def test_an_unstable_closed_loop_is_reported_without_margins():
    L = control.ss([[1.0]], [[1.0]], [[3.0]], 0.0, dt=TS)  # closed-loop pole 1 - 3 = -2
    m = _margins(L, 2.0)
    assert not m.stable and math.isnan(m.pm_deg)
    assert "unstable (rho = 2.0000)" in margin_table([m])


@pytest.fixture(scope="module")
def certified():
    return load_design(ROOT / "offline_design" / "designs" / "cm_certified")


def test_the_broken_loops_close_into_the_tube_loop(certified):
    """Each break closed by w = -y is the loop the design certifies with the notch."""
    verts = vertex_plants(certified)
    for s in notch_settings(certified):
        A_cl = closed_loop(verts.A, verts.B, s.F, s.notch, TS)
        if s.notch is not None:
            ref, _ = notch_closed_loop(verts.A, verts.B, s.F, s.notch, TS, IQ)
            np.testing.assert_allclose(A_cl, ref, rtol=0, atol=1e-12)
        for b in BREAKS:
            A_L, B_L, C_L = open_loop(verts.A, verts.B, s.F, s.notch, TS, b)
            np.testing.assert_allclose(A_L - B_L @ C_L, A_cl, rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="loop break"):
        open_loop(verts.A, verts.B, s.F, None, TS, "alpha")


def test_the_notch_lowers_the_q_loop_gain_at_omega_1_by_its_depth(certified):
    """At the q break the notch is in series: |L| at omega_1 drops by eps_z / eps_p (-14 dB)."""
    point = design_point_plant(certified)
    settings = {s.label: s for s in notch_settings(certified)}
    assert list(settings) == ["omega_1", "off", "omega_2", "omega_1, eps_p 0.5"]
    gains = {}
    for label in ("omega_1", "off", "omega_1, eps_p 0.5"):
        s = settings[label]
        L = loop_systems(point, s.F, s.notch, TS, "q")[0]
        rho = spectral_radius(closed_loop(point.A, point.B, s.F, s.notch, TS))[0]
        gains[label] = _margins(L, rho).gain_w1_db
    depth = 20.0 * math.log10(0.02 / 0.1)  # eps_z / eps_p at omega_z = 19.05 ~ omega_1
    assert gains["omega_1"] - gains["off"] == pytest.approx(depth, abs=0.1)  # -13.98 dB
    assert gains["omega_1, eps_p 0.5"] - gains["off"] == pytest.approx(
        20.0 * math.log10(0.02 / 0.5), abs=0.1)  # fmt: skip  (-27.96 dB)


def test_worst_case_takes_each_margin_at_its_worst():
    a = LoopMargins("q", "off", "vertex 0", 0.9, 1, 8.0, -10.0, 1.0, 50.0, 3.0, 30.0, 6.0, 40.0,
                    0.0)  # fmt: skip
    b = LoopMargins("q", "off", "vertex 1", 0.95, 1, 7.0, -12.0, 1.0, -46.0, 4.0, 20.0, 7.0, 35.0,
                    1.0)  # fmt: skip
    w = worst_case([a, b], "worst of 2 vertices")
    assert (w.gm_up_db, w.gm_down_db, w.pm_deg, w.delay_ms) == (7.0, -10.0, -46.0, 20.0)
    assert (w.dm_gain_db, w.dm_phase_deg, w.rho) == (6.0, 35.0, 0.95)
    assert meets(a) and not meets(replace_pm(a, 44.0))
    c = LoopMargins("q", "off", "vertex 2", 1.01)
    assert not worst_case([a, c], "w").stable


def replace_pm(m: LoopMargins, pm: float) -> LoopMargins:
    """``m`` with another phase margin."""
    from dataclasses import replace

    return replace(m, pm_deg=pm)
