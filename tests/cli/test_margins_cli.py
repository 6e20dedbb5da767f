"""``fahv margins``: the table of cm_certified and its figures; of a scenario with an
estimator, the elevator loop on the estimate too."""

from __future__ import annotations

import re

import pytest

from fahv.cli import main
from fahv.sil.workspace import ROOT


def test_margins_prints_the_table_and_writes_the_figures(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    # case1_kalman: its design cm_certified, and its filter on h, V, theta and q
    kalman = "studies/kalman_exact_design/scenarios/case1_kalman.yaml"
    assert main(["margins", kalman, "--out", str(tmp_path), "--format", "pdf"]) == 0
    out = capsys.readouterr().out
    assert "GM+ [dB]" in out and "DM phase [deg]" in out
    rows = [line.split() for line in out.splitlines() if line.startswith(("delta_e ", "q "))]
    on_estimate = [r for r in rows if r[:3] == ["delta_e", "on", "x_hat"]]
    rows = [r for r in rows if r not in on_estimate]
    assert "the law on the Kalman estimate of h, V, theta, q (scenario case1_kalman" in out
    # 4 settings at the design point and worst over the vertices
    assert len(on_estimate) == 4 * 2
    dp = next(r for r in on_estimate if r[3:6] == ["omega_1", "design", "point"])
    assert float(dp[6]) == pytest.approx(5.0, abs=0.1) and float(dp[8]) == pytest.approx(30.1,
                                                                                      abs=0.3)
    # the classical requirement said of the loop on the estimate too (5.0 dB, 30.1 deg)
    assert re.search(r"the loop on the estimate, break at delta_e on x_hat, notch omega_1, design "
                     r"point: GM\+ 5\.0 dB, PM 30\.1 deg; 6 dB / 45 deg met: no", out), out
    # 2 breaks x (4 settings at the design point and the corner, 2 over the vertices)
    assert len(rows) == 2 * (4 * 2 + 2)
    q_on = next(r for r in rows if r[:4] == ["q", "omega_1", "design", "point"])
    q_off = next(r for r in rows if r[:4] == ["q", "off", "design", "point"])
    assert float(q_on[-1]) - float(q_off[-1]) == pytest.approx(-14.0, abs=0.15)
    assert re.search(r"break at q: .* \(-14\.0 dB\)", out)
    assert "stable at 1024 of 1024 parameter box corners" in out
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["margins_cm_certified_bode_delta_e.pdf", "margins_cm_certified_bode_q.pdf",
                     "margins_cm_certified_estimate_nichols.pdf",
                     "margins_cm_certified_nichols.pdf"]  # fmt: skip
    assert all((tmp_path / n).stat().st_size > 10_000 for n in names)
