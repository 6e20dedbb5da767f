"""Two campaigns of the same draws compared run by run (fahv campaign compare)."""

import pytest
from scipy.stats import binomtest

from fahv.campaign import store
from fahv.campaign.compare import compare_campaigns, requirement_pairs
from fahv.cli import main
from fahv.errors import CampaignError

REQ = {"attitude_deg": 0.5, "settling_s": 60.0, "h_final_ft": 10.0, "V_final_fps": 2.0,
       "confidence": 0.95}  # fmt: skip


def _row(i: int, attitude: float, tube: float = 1.0, variant: str = "tube_mpc") -> dict:
    return {"index": i, "variant": variant, "status": "ok", "alpha_err_max_deg": attitude,
            "theta_err_max_deg": 0.1, "tube_fraction_inside": tube,
            "settling_after_command_s": 30.0 + i % 7, "input_limit_violations": 0,
            "h_err_final_ft": 0.5, "V_err_final_fps": 0.1}  # fmt: skip


def _folder(path, rows, seed=7, name="s"):
    path.mkdir()
    store.write_manifest(path, {"campaign": {"seed": seed, "dispersions": {"fault": {}},
                                             "requirements": REQ, "variants": ["tube_mpc"]},
                                "case": {"name": name}})  # fmt: skip
    store.write_part(path, store.RESULTS, "part-001-00000", rows)
    return path


def _pair(tmp_path):
    """40 runs: A misses the attitude at 0-9, B at 5-7 and 30-31 (and its tube at 0-2)."""
    a = [_row(i, 0.55 if i < 10 else 0.45) for i in range(40)]
    b = [_row(i, 0.55 if 5 <= i < 8 or i in (30, 31) else 0.45, 0.0 if i < 3 else 1.0)
         for i in range(40)]  # fmt: skip
    return _folder(tmp_path / "a", a, name="first"), _folder(tmp_path / "b", b, name="mean")


def test_each_requirement_is_counted_pair_by_pair(tmp_path):
    """Attitude: 30 / 35 passing, 2 only in A, 7 only in B, McNemar p = binomtest(2, 9);
    every requirement but the tube: B's tube misses do not count there, they do in all; the
    servos' rate, which no row carries, is left out."""
    _, _ = _pair(tmp_path)
    rows_a = store.read_rows(tmp_path / "a")
    rows_b = store.read_rows(tmp_path / "b")
    got = {r.key: r for r in requirement_pairs(rows_a, rows_b, REQ)}
    att = got["attitude"]
    assert (att.n, att.pass_a, att.pass_b, att.only_a, att.only_b) == (40, 30, 35, 2, 7)
    assert att.p_mcnemar == pytest.approx(binomtest(2, 9, 0.5).pvalue, rel=1e-12)
    assert att.ci_b[0] < 35 / 40 < att.ci_b[1]
    assert (got["all_but_tube"].pass_a, got["all_but_tube"].pass_b) == (30, 35)
    assert (got["all"].pass_a, got["all"].pass_b) == (30, 32)  # B fails its tube at 0-2
    assert got["settling"].p_mcnemar == 1.0 and got["settling"].pass_b == 40
    assert "input_rates" not in got  # no row has the servos' rate metric: left out


def test_the_command_prints_the_table_and_the_paired_metrics(tmp_path, capsys):
    a, b = _pair(tmp_path)
    assert main(["campaign", "compare", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    assert "B (" in out and ", tube_mpc, scenario mean) against A (" in out
    assert "| attitude error within +/- 0.5 deg | 30 [" in out
    assert "| 2 | 7 | 0.18 |" in out  # binomtest(2, 9): p = 0.1797
    assert "## Paired comparison: B (b, tube_mpc) - A (a, tube_mpc)" in out


def test_campaigns_of_other_draws_are_refused(tmp_path):
    a, _ = _pair(tmp_path)
    other = _folder(tmp_path / "c", [_row(i, 0.4) for i in range(40)], seed=8)
    with pytest.raises(CampaignError, match=r"differ in the campaign key 'seed'"):
        compare_campaigns(a, other)
    with pytest.raises(CampaignError, match=r"is not a campaign folder"):
        compare_campaigns(a, tmp_path / "nowhere")
    with pytest.raises(CampaignError, match=r"variant 'rmpc' is not in .*a \(its variants"):
        compare_campaigns(a, tmp_path / "b", "rmpc")
    with pytest.raises(CampaignError, match=r"variant 'rmpc' is not in .*b \(its variants"):
        compare_campaigns(a, tmp_path / "b", "tube_mpc", "rmpc")


def test_a_law_is_compared_with_another_from_its_own_campaign(tmp_path):
    """Variant W of B against variant V of A, on the same draws."""
    a, _ = _pair(tmp_path)
    other = _folder(tmp_path / "c", [_row(i, 0.4, variant="rmpc") for i in range(40)])
    (tmp_path / "c" / store.MANIFEST).write_text((tmp_path / "c" / store.MANIFEST).read_text()
                                                 .replace('"tube_mpc"', '"rmpc"'))  # fmt: skip
    lines, pairs = compare_campaigns(a, other, "tube_mpc", "rmpc")
    att = {p.key: p for p in pairs}["attitude"]
    assert (att.pass_a, att.pass_b, att.only_a, att.only_b) == (30, 40, 0, 10)
    assert lines[0].startswith("# B (") and ", rmpc, scenario s) against A (" in lines[0]


def test_a_plants_rate_limit_is_not_applicable_against_ideal_actuators(tmp_path, capsys):
    """Ideal actuators (A: no rate limit, the metric NaN) against servos (B: 38 of 40 runs
    within the rate): the servos' rate is n/a on A's side, neither counted as 0 passes
    nor tested; every requirement but the tube still counts B's two rate misses."""
    a = [dict(_row(i, 0.45), input_rate_violations=float("nan")) for i in range(40)]
    b = [dict(_row(i, 0.45), input_rate_violations=3 if i < 2 else 0) for i in range(40)]
    a, b = _folder(tmp_path / "a", a), _folder(tmp_path / "b", b)
    got = {r.key: r for r in requirement_pairs(store.read_rows(a), store.read_rows(b), REQ)}
    rates = got["input_rates"]
    assert (rates.pass_a, rates.pass_b, rates.only_a, rates.only_b) == (None, 38, None, None)
    assert rates.ci_b[0] < 38 / 40 < rates.ci_b[1]
    assert (got["all_but_tube"].pass_a, got["all_but_tube"].pass_b) == (40, 38)
    assert main(["campaign", "compare", str(a), str(b)]) == 0
    assert "| commands within the servos' rate limits | n/a | 38 [" in capsys.readouterr().out


def test_a_requirement_one_dataset_lacks_is_not_applicable_there(tmp_path, capsys):
    """A's dataset predates the tube metric (no row has it), B's has it with 3 misses: the
    tube is n/a on A's side (not 0 of 40 passing, no McNemar test), counted on B's; and
    `--write` writes the comparison that the command prints."""
    a = [{k: v for k, v in _row(i, 0.45).items() if k != "tube_fraction_inside"}
         for i in range(40)]  # fmt: skip
    b = [_row(i, 0.45, 0.0 if i < 3 else 1.0) for i in range(40)]
    a, b = _folder(tmp_path / "a", a), _folder(tmp_path / "b", b)
    got = {r.key: r for r in requirement_pairs(store.read_rows(a), store.read_rows(b), REQ)}
    tube = got["tube"]
    assert (tube.pass_a, tube.pass_b, tube.only_a, tube.only_b) == (None, 37, None, None)
    out = tmp_path / "evidence" / "compare.md"
    assert main(["campaign", "compare", str(a), str(b), "--write", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "| tube error inside Z at every step | n/a | 37 [" in printed
    assert out.read_text() == printed.split(f"comparison written to {out}")[0]
