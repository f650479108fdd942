"""Paired statistics: the t-interval and p against scipy.stats.t directly, Holm on a textbook
example, verdicts on constructed sweeps, interval coverage by simulation, failed runs."""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow as pa
import pytest
from scipy import stats as sps

from sim2radar.experiment.stats import (
    COVERAGE_NOTE,
    DEFAULT_METRIC,
    holm_adjust,
    paired_comparison,
    sweep_stats,
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
    # identical runs: no difference at all
    same = _sweep(0.0, diff_sd=0.0)
    res = sweep_stats(same)
    assert all(c["verdict"] == "no detectable difference" and c["p"] == 1.0 and c["d_z"] is None
               and c["t_ci"] == [0.0, 0.0] for c in res["comparisons"])


def test_interval_coverage_simulation():
    """2,000 synthetic 5-pair sweeps: the 95 % t-interval covers the true mean difference in
    93-97 % of them; the bootstrap interval clearly less often (~84 %, COVERAGE_NOTE)."""
    rng = np.random.default_rng(12345)
    n_sweeps, true = COVERAGE_NOTE["sweeps"], 1.5
    base = rng.normal(40.0, 6.0, (n_sweeps, COVERAGE_NOTE["n_pairs"]))
    treated = base + rng.normal(true, 3.0, base.shape)
    s = paired_comparison(treated, base, n_resamples=9999, seed=1)
    cov_t = np.mean((s["t_lo"] <= true) & (true <= s["t_hi"]))
    cov_b = np.mean((s["boot_lo"] <= true) & (true <= s["boot_hi"]))
    assert 0.93 <= cov_t <= 0.97, cov_t
    assert cov_b < 0.90 and cov_b < cov_t - 0.05, (cov_b, cov_t)
    assert abs(cov_b - COVERAGE_NOTE["bootstrap"]) < 0.03, cov_b  # the figure the notes quote


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
                         "notes"]
    assert res["metric"] == DEFAULT_METRIC == "ap_3d_r40_iou03" and res["alpha"] == 0.05
    assert res["conditions"] == ["baseline", "sim-pretrain"]
    assert res["fractions"] == list(FRACTIONS)
    assert set(res["cells"][0]) == {"condition", "fraction", "n_real_frames", "sim_real_ratio",
                                    "n", "n_failed", "mean", "std", "values", "trials"}
    assert set(res["comparisons"][0]) == {
        "condition", "fraction", "n_pairs", "mean_diff", "t_ci", "bootstrap_ci", "p", "p_holm",
        "d_z", "k_improved", "verdict", "differences", "trials"}
    json.dumps(res, allow_nan=False)  # strict JSON
    cell = res["cells"][5]  # sim-pretrain at 5 %
    assert cell["sim_real_ratio"] == pytest.approx(15.0) and cell["n_real_frames"] == 18
    assert cell["std"] == pytest.approx(np.std(cell["values"], ddof=1))
    assert res["cells"][0]["sim_real_ratio"] is None
    assert any("0.0625" in n for n in res["notes"])
    assert any("anti-conservative" in n and "84 %" in n for n in res["notes"])
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
