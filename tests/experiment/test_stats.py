"""Paired statistics: the t-interval and p against scipy.stats.t directly, Holm on a textbook
example, verdicts on constructed sweeps, interval coverage by simulation, failed runs; the
minimum detectable effect and the trials a given effect needs against simulated paired
experiments, P(improvement)'s exact interval, the degenerate (zero-spread) case."""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow as pa
import pytest
from scipy import stats as sps

from sim2radar.experiment.stats import (
    DEFAULT_METRIC,
    DEGENERATE,
    PAPER_DELTA_AP,
    holm_adjust,
    interval_coverage,
    minimum_detectable_dz,
    minimum_detectable_effect,
    paired_comparison,
    paired_t_power,
    proportion_improved,
    sweep_stats,
    trials_to_detect,
)

FRACTIONS = (0.05, 0.10, 0.25, 0.50, 1.00)
N_REAL = (18, 37, 92, 185, 371)


def _sweep(diff_mean, diff_sd=1.0, trials=5, seed=0, baseline_sd=5.0):
    """Runs of a constructed sweep: baseline AP rises with the fraction; the condition adds a
    per-trial difference ~ N(diff_mean[f], diff_sd)."""
    rng = np.random.default_rng(seed)
    rows = []
    for i, (f, n) in enumerate(zip(FRACTIONS, N_REAL, strict=True)):
        mu = diff_mean[i] if np.ndim(diff_mean) else diff_mean
        for t in range(trials):
            base = 10 + 50 * f + rng.normal(0, baseline_sd)
            for cond, ap in (("baseline", base), ("sim-pretrain", base + rng.normal(mu, diff_sd))):
                rows.append({"condition": cond, "fraction": f, "trial": t, "seed": 1000 + t,
                             "n_real_frames": n, "n_sim_frames": 0 if cond == "baseline" else 270,
                             "sim_real_ratio": None if cond == "baseline" else 270 / n,
                             "ap_3d_r40_iou03": ap, "ap_3d_r11_iou03": ap + 1.0,
                             "status": "ok", "error": ""})
    return rows


def test_t_interval_and_p_equal_a_direct_computation():
    base = np.array([30.1, 28.4, 35.0, 31.7, 29.9])
    d = np.array([1.2, 3.4, -0.5, 2.2, 1.9])
    s = paired_comparison(base + d, base, n_resamples=0)
    n, mean, sd = 5, d.mean(), d.std(ddof=1)
    half = sps.t.ppf(0.975, n - 1) * sd / math.sqrt(n)
    assert float(s["mean_diff"]) == pytest.approx(1.64)
    assert float(s["t_lo"]) == pytest.approx(mean - half, rel=1e-12)
    assert float(s["t_hi"]) == pytest.approx(mean + half, rel=1e-12)
    t = mean / (sd / math.sqrt(n))
    assert float(s["p"]) == pytest.approx(2 * sps.t.sf(abs(t), n - 1), rel=1e-10)
    assert float(s["d_z"]) == pytest.approx(mean / sd)
    assert int(s["k_improved"]) == 4
    # the same numbers through sweep_stats, for one fraction
    rows = [{"condition": c, "fraction": 0.5, "trial": i, "ap_3d_r40_iou03": v, "status": "ok"}
            for i in range(5) for c, v in (("baseline", base[i]), ("sim-pretrain", base[i] + d[i]))]
    comp = sweep_stats(rows)["comparisons"][0]
    assert comp["t_ci"] == pytest.approx([mean - half, mean + half])
    assert comp["p"] == pytest.approx(comp["p_holm"])  # one fraction: Holm changes nothing
    assert comp["differences"] == pytest.approx(list(d)) and comp["trials"] == list(range(5))
    assert comp["bootstrap_ci"][0] < mean < comp["bootstrap_ci"][1]


def test_holm_textbook_example():
    """Holm (1979) as in e.g. Wikipedia's example: p = 0.01, 0.04, 0.03, 0.005 (m = 4).
    Sorted: 0.005 x 4 = 0.02, 0.01 x 3 = 0.03, 0.03 x 2 = 0.06, max(0.04 x 1, 0.06) = 0.06:
    at alpha 0.05 hypotheses 1 and 4 are rejected."""
    assert holm_adjust([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    # undefined p-values stay out of the family; adjusted values are capped at 1
    assert holm_adjust([None, 0.01, 0.4]) == [None, pytest.approx(0.02), pytest.approx(0.4)]
    assert holm_adjust([0.5, 0.6, 0.7]) == pytest.approx([1.0, 1.0, 1.0])
    assert holm_adjust([]) == []


def test_verdicts_on_constructed_sweeps():
    gain = sweep_stats(_sweep(5.0, diff_sd=0.5))
    assert [c["verdict"] for c in gain["comparisons"]] == ["gain"] * 5
    assert all(c["k_improved"] == 5 and c["t_ci"][0] > 0 for c in gain["comparisons"])
    loss = sweep_stats(_sweep(-5.0, diff_sd=0.5))
    assert [c["verdict"] for c in loss["comparisons"]] == ["loss"] * 5
    # noise: a zero true difference with a spread of 3 AP points
    noise = sweep_stats(_sweep(0.0, diff_sd=3.0, seed=2))
    assert [c["verdict"] for c in noise["comparisons"]] == ["no detectable difference"] * 5
    # by chance the 10 % comparison's raw p is below 0.05 (its unadjusted interval excludes 0);
    # Holm across the 5 fractions keeps it from being called a loss
    c10 = noise["comparisons"][1]
    assert c10["p"] < 0.05 and c10["t_ci"][1] < 0 and c10["p_holm"] > 0.05
    # a gain at one fraction only, the rest noise
    mixed = sweep_stats(_sweep([8.0, 0, 0, 0, 0], diff_sd=1.0, seed=7))
    assert [c["verdict"] for c in mixed["comparisons"]] == (
        ["gain"] + ["no detectable difference"] * 4)
    # Holm: the adjusted p is never below the raw p, and the smallest is scaled by 5
    comps = mixed["comparisons"]
    assert all(c["p_holm"] >= c["p"] for c in comps)
    assert comps[0]["p_holm"] == pytest.approx(5 * comps[0]["p"])
    # identical runs: differences all 0, no spread: no test (t = 0/0), not "no difference"
    same = _sweep(0.0, diff_sd=0.0)
    res = sweep_stats(same)
    assert all(c["verdict"] == DEGENERATE and c["p"] is None and c["p_holm"] is None
               and c["d_z"] is None and c["t_ci"] == [None, None] and c["mde"] is None
               for c in res["comparisons"])


def test_interval_coverage_simulation():
    """2,000 synthetic 5-pair sweeps (another seed, another mean and sd, 9,999 resamples):
    the 95 % t-interval covers the true mean difference in 93-97 % of them; the bootstrap
    interval clearly less often, as often as interval_coverage (the figure the notes quote)
    says."""
    rng = np.random.default_rng(12345)
    n_sweeps, n_pairs, true = 2000, 5, 1.5
    base = rng.normal(40.0, 6.0, (n_sweeps, n_pairs))
    treated = base + rng.normal(true, 3.0, base.shape)
    s = paired_comparison(treated, base, n_resamples=9999, seed=1)
    cov_t = np.mean((s["t_lo"] <= true) & (true <= s["t_hi"]))
    cov_b = np.mean((s["boot_lo"] <= true) & (true <= s["boot_hi"]))
    assert 0.93 <= cov_t <= 0.97, cov_t
    assert cov_b < 0.90 and cov_b < cov_t - 0.05, (cov_b, cov_t)
    quoted = interval_coverage(n_pairs)
    assert quoted.n_pairs == 5 and 0.93 <= quoted.t <= 0.97
    assert abs(cov_b - quoted.bootstrap) < 0.03, (cov_b, quoted)


def test_bootstrap_coverage_note_is_for_the_sweeps_own_n():
    """The audit's case: a 3-pair sweep must not quote the 5-pair coverage. With 3 pairs the
    BCa interval covers far less (~73 %) than with 5 (~85 %) or 10 (~90 %)."""
    cov = {n: interval_coverage(n) for n in (3, 5, 10)}
    assert cov[3].bootstrap < cov[5].bootstrap < cov[10].bootstrap < 0.95
    assert 0.65 < cov[3].bootstrap < 0.80 and all(0.93 <= c.t <= 0.97 for c in cov.values())
    assert interval_coverage(3) is cov[3]                      # cached: simulated once per n
    res = sweep_stats(_sweep(2.0, trials=3, seed=4))
    (note,) = [n for n in res["notes"] if "bootstrap" in n]
    assert f"{100 * cov[3].bootstrap:.0f} % with 3 pairs" in note and "anti-conservative" in note
    assert "5 pairs" not in note
    assert all(c["bootstrap_coverage"] == cov[3].bootstrap for c in res["comparisons"])
    with pytest.raises(ValueError, match="n_pairs >= 2"):
        interval_coverage(1)


def test_failed_runs_are_counted_and_excluded():
    rows = _sweep(5.0, diff_sd=0.5)
    # trial 0 of sim-pretrain at 5 % failed; trial 1 of baseline at 10 % has a null AP
    for r in rows:
        if (r["condition"], r["fraction"], r["trial"]) == ("sim-pretrain", 0.05, 0):
            r.update(status="failed", ap_3d_r40_iou03=None, error="NonFiniteLoss")
        if (r["condition"], r["fraction"], r["trial"]) == ("baseline", 0.10, 1):
            r.update(ap_3d_r40_iou03=float("nan"))
    # a failed attempt later retried successfully counts as a success
    retry = dict(rows[0], status="failed", ap_3d_r40_iou03=None)
    res = sweep_stats([retry, *rows])
    cells = {(c["condition"], c["fraction"]): c for c in res["cells"]}
    assert (cells[("sim-pretrain", 0.05)]["n"], cells[("sim-pretrain", 0.05)]["n_failed"]) == (4, 1)
    assert cells[("sim-pretrain", 0.05)]["trials"] == [1, 2, 3, 4]
    assert (cells[("baseline", 0.10)]["n"], cells[("baseline", 0.10)]["n_failed"]) == (4, 1)
    assert (cells[("baseline", 0.05)]["n"], cells[("baseline", 0.05)]["n_failed"]) == (5, 0)
    comps = {c["fraction"]: c for c in res["comparisons"]}
    assert comps[0.05]["n_pairs"] == 4 and comps[0.05]["trials"] == [1, 2, 3, 4]
    assert comps[0.10]["n_pairs"] == 4 and 1 not in comps[0.10]["trials"]
    assert comps[0.25]["n_pairs"] == 5
    assert any("2 failed run(s) excluded" in n for n in res["notes"])
    # one pair left: no test
    few = [r for r in rows if r["trial"] == 0 or r["condition"] == "baseline"]
    few = [r for r in few if r["fraction"] != 0.05]
    res = sweep_stats(few)
    assert all(c["verdict"] == "insufficient trials" and c["p"] is None and c["p_holm"] is None
               and c["t_ci"] == [None, None] for c in res["comparisons"])


def test_output_structure_metric_choice_and_table_input():
    rows = _sweep(2.0, seed=4)
    res = sweep_stats(rows)
    assert list(res) == ["metric", "alpha", "conditions", "fractions", "cells", "comparisons",
                         "pooled", "primary", "power", "notes"]
    assert res["power"]["power"] == 0.8 and res["power"]["source"].startswith("paper Table 1")
    assert res["metric"] == DEFAULT_METRIC == "ap_3d_r40_iou03" and res["alpha"] == 0.05
    assert res["conditions"] == ["baseline", "sim-pretrain"]
    assert res["fractions"] == list(FRACTIONS)
    assert set(res["cells"][0]) == {"condition", "fraction", "n_real_frames", "sim_real_ratio",
                                    "n", "n_failed", "mean", "std", "values", "trials"}
    assert set(res["comparisons"][0]) == {
        "condition", "fraction", "n_pairs", "mean_diff", "sd_diff", "t_ci",
        "t_ci_simultaneous", "bootstrap_ci",
        "bootstrap_coverage", "p", "p_holm", "d_z", "k_improved", "p_improved",
        "p_improved_ci", "verdict", "mde", "mde_dz", "mde_alpha", "mde_note", "paper_delta",
        "n_for_paper_delta", "n_for_paper_delta_note", "differences", "trials"}
    json.dumps(res, allow_nan=False)  # strict JSON
    cell = res["cells"][5]  # sim-pretrain at 5 %
    assert cell["sim_real_ratio"] == pytest.approx(15.0) and cell["n_real_frames"] == 18
    assert cell["std"] == pytest.approx(np.std(cell["values"], ddof=1))
    assert res["cells"][0]["sim_real_ratio"] is None
    assert any("0.0625" in n for n in res["notes"])
    cov5 = interval_coverage(5)
    assert any("anti-conservative" in n and f"{100 * cov5.bootstrap:.0f} % with 5 pairs" in n
               for n in res["notes"])
    # a pyarrow Table gives the same result
    assert sweep_stats(pa.Table.from_pylist(rows)) == res
    # R11 instead of R40: every value moves by +1 in this construction, differences do not
    r11 = sweep_stats(rows, metric="ap_3d_r11_iou03")
    assert r11["metric"] == "ap_3d_r11_iou03"
    assert r11["cells"][0]["mean"] == pytest.approx(res["cells"][0]["mean"] + 1.0)
    assert r11["comparisons"][0]["mean_diff"] == pytest.approx(res["comparisons"][0]["mean_diff"])
    with pytest.raises(ValueError, match="metric"):
        sweep_stats(rows, metric="ap_3d")
    clash = dict(rows[0], ap_3d_r40_iou03=rows[0]["ap_3d_r40_iou03"] + 1)
    with pytest.raises(ValueError, match="two different results"):
        sweep_stats([*rows, clash])


# ------------------------------------------------------------------------------ power
def _rejection_rate(effect, sd, n, alpha, experiments=20_000, seed=0):
    """Share of simulated paired experiments (n normal differences, mean ``effect``, sd
    ``sd``) in which the two-sided paired t-test rejects at ``alpha``."""
    rng = np.random.default_rng(seed)
    base = rng.normal(30.0, 5.0, (experiments, n))
    treated = base + rng.normal(effect, sd, (experiments, n))
    return float(np.mean(sps.ttest_rel(treated, base, axis=-1).pvalue < alpha))


@pytest.mark.parametrize("n,alpha,sd", [(3, 0.05 / 5, 2.0), (5, 0.05, 3.0), (5, 0.05 / 5, 1.0),
                                        (10, 0.05 / 3, 4.0)])
def test_mde_is_detected_with_80_percent_power_in_simulated_experiments(n, alpha, sd):
    """20,000 simulated paired experiments with the true mean difference at the MDE: the
    t-test rejects in 80 % +- 2 % of them (binomial SE 0.3 %); at half the MDE clearly less
    often, and the power function agrees with the simulation at both."""
    mde = minimum_detectable_effect(n, sd, alpha)
    assert mde.note is None and mde.mde == pytest.approx(mde.mde_dz * sd)
    rate = _rejection_rate(mde.mde, sd, n, alpha, seed=n)
    assert abs(rate - 0.80) <= 0.02, rate
    half = _rejection_rate(mde.mde / 2, sd, n, alpha, seed=n + 100)
    assert half < 0.6 and abs(half - paired_t_power(mde.mde_dz / 2, n, alpha)) < 0.02
    # a negative effect of the same size is detected as often (two-sided)
    assert abs(_rejection_rate(-mde.mde, sd, n, alpha, seed=n + 200) - 0.80) <= 0.02


def test_mde_known_values_and_limits():
    # G*Power / Cohen's tables, paired two-sided t at alpha 0.05, power 0.8: d_z = 1.68 at
    # n = 5, 1.00 at n = 10; the power at no effect is alpha
    assert minimum_detectable_dz(5, 0.05) == pytest.approx(1.682, abs=2e-3)
    assert minimum_detectable_dz(10, 0.05) == pytest.approx(0.996, abs=2e-3)
    assert paired_t_power(0.0, 5, 0.05) == pytest.approx(0.05)
    # more pairs or a looser level: a smaller MDE
    assert minimum_detectable_dz(3, 0.01) > minimum_detectable_dz(5, 0.01) > \
        minimum_detectable_dz(5, 0.05)
    # n = 2 at alpha / 5: a single degree of freedom needs a huge effect, and scipy's far
    # lower tail (NaN from nct.cdf) does not break the root search
    assert 50 < minimum_detectable_dz(2, 0.01) < 70


def test_no_mde_below_two_pairs_or_without_spread():
    one = minimum_detectable_effect(1, None, 0.05)
    assert one.mde is None and "at least 2" in one.note
    flat = minimum_detectable_effect(5, 0.0, 0.05)
    assert flat.mde is None and "identical (sd 0)" in flat.note
    assert minimum_detectable_effect(5, float("nan"), 0.05).mde is None
    with pytest.raises(ValueError, match="n >= 2"):
        minimum_detectable_dz(1, 0.05)
    with pytest.raises(ValueError, match="power"):
        minimum_detectable_effect(5, 1.0, 0.05, power=0.01)
    assert trials_to_detect(3.0, 0.0, 0.05).n is None
    assert trials_to_detect(0.0, 1.0, 0.05).n is None
    assert "unknown" in trials_to_detect(3.0, None, 0.05).note
    assert "more than 100" in trials_to_detect(0.01, 10.0, 0.01, max_n=100).note


@pytest.mark.parametrize("effect,sd,alpha", [(3.3, 3.0, 0.01), (0.9, 3.0, 0.01),
                                             (3.7, 1.0, 0.05)])
def test_trials_to_detect_is_the_smallest_n_with_80_percent_power(effect, sd, alpha):
    need = trials_to_detect(effect, sd, alpha)
    n = need.n
    assert paired_t_power(effect / sd, n, alpha) >= 0.8 > paired_t_power(effect / sd, n - 1,
                                                                          alpha)
    assert need.achieved_power == pytest.approx(paired_t_power(effect / sd, n, alpha))
    # consistent with the MDE: at n pairs the MDE is at most the effect, at n - 1 above it
    assert minimum_detectable_effect(n, sd, alpha).mde <= effect
    if n > 2:
        assert minimum_detectable_effect(n - 1, sd, alpha).mde > effect
    if n <= 40:  # and the simulation agrees
        assert _rejection_rate(effect, sd, n, alpha, experiments=20_000, seed=n) >= 0.78


def test_sweep_reports_mde_at_the_holm_family_level_and_trials_for_the_papers_delta():
    rows = _sweep([3.0, 1.0, 3.0, 1.0, 4.0], diff_sd=2.0, trials=3, seed=11)
    res = sweep_stats(rows)
    assert PAPER_DELTA_AP == {0.05: 3.3, 0.10: 0.9, 0.25: 3.2, 0.50: 1.2, 1.00: 3.7}
    for comp in res["comparisons"]:
        sd = np.std(comp["differences"], ddof=1)
        assert comp["sd_diff"] == pytest.approx(sd)
        assert comp["mde_alpha"] == pytest.approx(0.05 / 5)          # 5 fractions in the family
        assert comp["mde"] == pytest.approx(minimum_detectable_dz(3, 0.01) * sd)
        assert comp["paper_delta"] == PAPER_DELTA_AP[comp["fraction"]]
        assert comp["n_for_paper_delta"] == trials_to_detect(comp["paper_delta"], sd, 0.01).n
    # one fraction's differences all equal (+2.0): its own verdict, no p, out of the family
    for r in rows:
        if r["fraction"] == 0.25 and r["condition"] == "sim-pretrain":
            base = next(b for b in rows if b["condition"] == "baseline"
                        and b["fraction"] == 0.25 and b["trial"] == r["trial"])
            r["ap_3d_r40_iou03"] = base["ap_3d_r40_iou03"] + 2.0
    res = sweep_stats(rows)
    flat = res["comparisons"][2]
    assert flat["verdict"] == DEGENERATE and flat["p"] is None and flat["p_holm"] is None
    assert flat["mean_diff"] == pytest.approx(2.0) and flat["t_ci"] == [None, None]
    assert flat["mde"] is None and "identical" in flat["mde_note"]
    assert flat["k_improved"] == 3 and flat["p_improved"] == 1.0
    others = [c for i, c in enumerate(res["comparisons"]) if i != 2]
    assert all(c["mde_alpha"] == pytest.approx(0.05 / 4) for c in others)   # family of 4
    assert max(c["p_holm"] for c in others) <= 1.0
    assert any(DEGENERATE in n for n in res["notes"])
    # a fraction the paper has no Δ for
    odd = [dict(r, fraction=0.2) for r in rows if r["fraction"] == 0.05]
    comp = sweep_stats(odd)["comparisons"][0]
    assert comp["paper_delta"] is None and comp["n_for_paper_delta"] is None
    assert "no Δ" in comp["n_for_paper_delta_note"]
    json.dumps(res, allow_nan=False)


def test_identical_nonzero_differences_are_not_a_gain():
    """The audit's case: every trial +1.5 AP gave p = 0 and a 'gain'. Also where float
    rounding leaves a spread of ~1e-15 (AP + 1.5 - AP is not exactly 1.5)."""
    base = np.array([31.7, 28.3, 44.1, 0.1, 12.345])
    assert 0 < np.std((base + 1.5) - base, ddof=1) < 1e-14     # rounding: not exactly 0
    s = paired_comparison(base + 1.5, base, n_resamples=0)
    assert bool(s["flat"]) and np.isnan(s["p"]) and np.isnan(s["t_lo"])
    rows = [{"condition": c, "fraction": 0.5, "trial": t, "ap_3d_r40_iou03": v, "status": "ok"}
            for t, b in enumerate(base) for c, v in (("baseline", b), ("sim-pretrain", b + 1.5))]
    (comp,) = sweep_stats(rows)["comparisons"]
    assert comp["verdict"] == DEGENERATE == "identical differences: no test possible"
    assert comp["p"] is None and comp["mde"] is None and comp["k_improved"] == 5


def test_p_improved_has_a_clopper_pearson_interval():
    share, (lo, hi) = proportion_improved(3, 3)
    # Clopper-Pearson with k = n: lower bound (alpha / 2)^(1 / n), upper bound 1
    assert share == 1.0 and lo == pytest.approx(0.025 ** (1 / 3)) and hi == 1.0
    share, (lo, hi) = proportion_improved(2, 5)
    assert share == 0.4
    assert lo == pytest.approx(sps.beta.ppf(0.025, 2, 4)) and hi == pytest.approx(
        sps.beta.ppf(0.975, 3, 3))
    assert proportion_improved(0, 0) == (None, [None, None])
    res = sweep_stats(_sweep(5.0, diff_sd=0.5))
    comp = res["comparisons"][0]
    assert comp["k_improved"] == 5 and comp["p_improved"] == 1.0
    assert comp["p_improved_ci"] == pytest.approx([0.025 ** (1 / 5), 1.0])


def test_the_pooled_primary_endpoint_is_the_t_test_of_per_trial_mean_differences():
    """Pooled over 5/10/25 %: per trial the mean paired Δ of those fractions, then a one-sample
    t-test of the per-trial means (scipy.stats.ttest_1samp), at alpha without adjustment; a
    trial missing one of the fractions (failed run) is left out; the per-fraction comparisons
    carry the 1 - alpha/m interval."""
    rows = _sweep(2.0, seed=7)
    fail = next(r for r in rows if r["condition"] == "sim-pretrain" and r["fraction"] == 0.1
                and r["trial"] == 2)
    fail.update(status="failed", ap_3d_r40_iou03=None)
    res = sweep_stats(rows, n_resamples=0)
    assert res["primary"] == {"condition": "sim-pretrain", "fractions": [0.05, 0.1, 0.25]}
    (pooled,) = res["pooled"]
    ap = {(r["condition"], r["fraction"], r["trial"]): r["ap_3d_r40_iou03"] for r in rows}
    trials = sorted({r["trial"] for r in rows} - {2})
    d = [np.mean([ap[("sim-pretrain", f, t)] - ap[("baseline", f, t)]
                  for f in (0.05, 0.1, 0.25)]) for t in trials]
    ref = sps.ttest_1samp(d, 0.0)
    ci = ref.confidence_interval(0.95)
    assert pooled["trials"] == trials and pooled["primary"]
    assert pooled["mean_diff"] == pytest.approx(np.mean(d))
    assert pooled["p"] == pytest.approx(ref.pvalue)
    assert pooled["t_ci"] == pytest.approx([ci.low, ci.high])
    assert pooled["mde"] == pytest.approx(minimum_detectable_effect(
        len(d), np.std(d, ddof=1), 0.05).mde)
    assert pooled["verdict"] == ("gain" if ref.pvalue < 0.05 and np.mean(d) > 0 else
                                 "loss" if ref.pvalue < 0.05 else "no detectable difference")
    # the simultaneous interval of each fraction: 1 - alpha / m, m = 5 fractions
    for comp in res["comparisons"]:
        x = np.array([ap[("sim-pretrain", comp["fraction"], t)] for t in comp["trials"]])
        y = np.array([ap[("baseline", comp["fraction"], t)] for t in comp["trials"]])
        sim = sps.ttest_rel(x, y).confidence_interval(1 - 0.05 / 5)
        assert comp["t_ci_simultaneous"] == pytest.approx([sim.low, sim.high])
        lo, hi = comp["t_ci_simultaneous"]
        if lo > 0 or hi < 0:        # it excludes 0 only where Holm calls the fraction
            assert comp["verdict"] in ("gain", "loss")
    # explicit fractions and another primary condition
    other = sweep_stats(rows, n_resamples=0, primary_fractions=[0.5, 1.0],
                        primary_condition="sim-gt-pretrain")
    assert other["pooled"][0]["fractions"] == [0.5, 1.0] and not other["pooled"][0]["primary"]
