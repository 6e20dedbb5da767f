"""Paired comparison of two variants on common random numbers: differences run by run,
their confidence intervals, and the batches of a campaign interleaved by index range."""

import math

import numpy as np
import pytest
from scipy import stats

from fahv.campaign.engine import batches
from fahv.campaign.paired import paired_stats, paired_text


def _rows(n=200, seed=1):
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n):
        base = rng.normal(0.3, 0.05)
        for v, shift in (("a", 0.0), ("b", 0.1)):
            rows.append({
                "index": i, "variant": v, "status": "ok",
                "alpha_err_max_deg": base + shift, "theta_err_max_deg": base,
                "eta_1_dot_rms_after_fault": 0.02 + (0.005 if v == "b" else 0.0),
                "eta_2_dot_rms_after_fault": 0.02, "eta_1_dev_peak": 0.1,
                "Phi_min": 0.2, "Phi_max": 0.5, "delta_e_min_deg": 12.0, "delta_e_max_deg": 14.0,
                "h_err_final_ft": rng.normal(0.0, 1.0) + (50.0 if v == "b" else 0.0),
                "V_err_final_fps": -1.0,
                "settling_after_command_s": 30.0 if v == "a" else (math.nan if i % 2 else 40.0),
            })  # fmt: skip
    rows.append({"index": n, "variant": "a", "status": "ok"})  # no partner: left out
    rows.append({"index": n + 1, "variant": "a", "status": "failed"})
    return rows


def test_paired_differences_and_intervals():
    res = paired_stats(_rows(), "a", "b")
    assert res["n_pairs"] == 200
    assert res["settled"] == (1.0, 0.5)  # b never settles in the odd runs
    att = res["stats"]["attitude_deg"]
    assert att.mean_diff == pytest.approx(0.1, abs=1e-12)  # the same draw, shifted by 0.1
    assert att.t_ci[0] == pytest.approx(0.1, abs=1e-9) and att.frac_b_larger == 1.0
    h = res["stats"]["h_final_ft"]  # |N(50, 1)| - |N(0, 1)|, run by run
    xa, xb = res["values"]["h_final_ft"]
    d = xb - xa
    half = stats.t.ppf(0.975, d.size - 1) * d.std(ddof=1) / math.sqrt(d.size)
    assert h.t_ci == pytest.approx((d.mean() - half, d.mean() + half), rel=1e-12)
    assert h.boot_ci[0] == pytest.approx(h.t_ci[0], abs=0.3 * half)  # bootstrap ~ t here
    assert h.boot_ci[1] == pytest.approx(h.t_ci[1], abs=0.3 * half)
    assert abs(h.mean_diff - (50.0 - math.sqrt(2.0 / math.pi))) < 4 * half
    s = res["stats"]["settling_s"]
    assert s.n == 100 and s.mean_diff == pytest.approx(10.0)  # over runs settled in both
    text = "\n".join(paired_text(res, "a", "b"))
    assert r"| \|h - h_c\| at the end [ft] | 200 |" in text and "a 100.0 %, b 50.0 %" in text


def test_batches_interleave_the_variants_by_index_range():
    camp = {"batch_size": 2, "runs": 5, "variants": ["a", "b"]}
    out = batches(camp, {(0, "b")})
    assert out == [("a", [0, 1]), ("b", [1, 2]), ("a", [2, 3]), ("b", [3, 4]), ("a", [4])]


def test_completion_counts_and_pairs_with_envelope_exits():
    from fahv.campaign.paired import completion, pairs

    def row(i, v, ok, metrics=True):
        r = {"index": i, "variant": v, "status": "ok" if ok else "failed"}
        return {**r, "alpha_err_max_deg": 0.1} if metrics else r

    rows = [row(0, "a", True), row(0, "b", True), row(1, "a", True), row(1, "b", False),
            row(2, "a", True), row(2, "b", False, metrics=False), row(3, "a", False),
            row(3, "b", False), row(4, "a", True)]  # fmt: skip
    c = completion(rows, "a", "b")
    assert (c["n"], c["both"], c["only_a"], c["only_b"], c["neither"]) == (4, 1, 2, 0, 1)
    assert c["p_mcnemar"] == 0.5  # 2 discordant pairs, both one way: 2 * 0.5^2
    assert [i["index"] for i, _ in pairs(rows, "a", "b")] == [0]
    assert [i["index"] for i, _ in pairs(rows, "a", "b", completed=False)] == [0, 1, 3]
