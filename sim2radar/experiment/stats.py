"""Paired statistics of a sweep: per-cell mean ± std, and for every non-baseline condition and
fraction the paired difference to the baseline with its uncertainty, and what the design could
have detected (scipy only).

Design (what a reader of Table 1 needs to judge a "+1.2 AP" claim from 5 trials):

- **Pairing.** Trial ``t`` of every condition uses the same seed: the same real subset, head
  initialisation and data order (:mod:`sim2radar.experiment.subsets`). The unit of analysis is
  the per-trial difference ``d_t = AP(condition, t) - AP(baseline, t)``; pairs exist only where
  both runs finished.
- **Primary interval:** the 95 % Student-t interval of ``mean(d)`` (n - 1 degrees of freedom,
  ``scipy.stats.ttest_rel(...).confidence_interval``), and the paired t-test's p-value
  (``scipy.stats.ttest_rel``), Holm-adjusted across the fractions of each condition (Holm,
  Scand. J. Statist. 6, 1979). Verdict: ``"gain"`` / ``"loss"`` when the adjusted p < alpha
  (by the sign of ``mean(d)``), ``"no detectable difference"`` otherwise, ``"insufficient
  trials"`` below 2 pairs, and :data:`DEGENERATE` where every pair differs by the same amount
  (sample sd 0 up to :data:`ZERO_SPREAD_AP`): the t statistic is 0/0 there, so there is no
  p-value, interval or verdict, and the comparison leaves the Holm family.
- **Minimum detectable effect** (MDE): the smallest true mean difference the two-sided paired
  t-test detects with :data:`POWER` (80 %) power, given the comparison's n pairs and taking the
  observed sd of its differences as the true sd (the usual plug-in of a post-hoc power
  analysis; at n = 3 that sd is itself uncertain by a factor of ~2). Power is the noncentral t
  (``scipy.stats.nct``): under a true mean difference ``delta`` the statistic
  ``T = mean(d) / (sd(d) / sqrt(n))`` follows ``nct(df = n - 1, nc = delta sqrt(n) / sigma)``
  (Cohen, *Statistical Power Analysis for the Behavioral Sciences*, 2nd ed. 1988, ch. 2, the
  paired case; Owen, "The power of Student's t-test", JASA 60, 1965), so
  ``power = P(T > t_c) + P(T < -t_c)`` with ``t_c = t.isf(level / 2, n - 1)``;
  ``scipy.optimize.brentq`` solves ``power = 0.8``.
  **Level:** ``alpha / m``, ``m`` the number of fractions in the condition's Holm family (those
  with a p-value). That is the first step of Holm's procedure, the level at which the verdict
  calls a fraction whatever the other fractions show (a p below ``alpha / m`` is rejected at
  every step). Holm's later steps (``alpha / (m - r + 1)`` for the r-th smallest p) apply only
  once the smaller p-values were rejected, so they give no unconditional power; the stated MDE
  is therefore the one the verdict is sure to reach, an upper bound of Holm's own. The same
  level and sd give the number of trials that would detect the paper's Δ at that fraction
  (:data:`PAPER_DELTA_AP`).
- **P(improvement):** the share of pairs in which the condition beat the baseline (``k/n``),
  with its Clopper–Pearson interval (``scipy.stats.binomtest(k, n).proportion_ci(method=
  "exact")``; Clopper & Pearson, Biometrika 26, 1934). Exact rather than Wilson: with 3-5
  pairs Wilson's coverage falls below the nominal level for some true shares, Clopper–Pearson's
  never does (Brown, Cai & DasGupta, "Interval estimation for a binomial proportion",
  Statist. Sci. 16, 2001).
- **Effect size:** ``d_z = mean(d) / sd(d)`` (Cohen's d for paired samples).
- **Bootstrap interval** (``scipy.stats.bootstrap``, BCa, over the paired differences) for
  reference only: with few pairs it is anti-conservative (it resamples n values, whose spread
  under-states the population's). :func:`interval_coverage` measures its coverage at the
  sweep's own n by a seeded simulation; the notes quote it.
- **Rank tests** are not used: with n pairs a sign or Wilcoxon signed-rank test cannot go below
  a two-sided p of ``2 / 2**n`` (0.0625 at n = 5), so they could never reach 0.05.

Failed runs (status ``failed`` or a null/NaN metric) are excluded and counted per cell.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import math
import warnings
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from scipy import optimize
from scipy import stats as sps

from sim2radar.experiment.documents import SweepDocument
from sim2radar.experiment.profiles import BASELINE, CONDITIONS, default_primary_fractions

__all__ = [
    "AP_METRICS",
    "COVERAGE_SWEEPS",
    "DEFAULT_METRIC",
    "DEGENERATE",
    "MDE",
    "PAPER_DELTA_AP",
    "POWER",
    "VERDICTS",
    "Coverage",
    "TrialsNeeded",
    "as_rows",
    "holm_adjust",
    "interval_coverage",
    "minimum_detectable_dz",
    "minimum_detectable_effect",
    "paired_comparison",
    "paired_t_power",
    "paper_delta",
    "proportion_improved",
    "stats_count_runs",
    "sweep_statistics",
    "sweep_stats",
    "trials_to_detect",
]

#: experiment_runs AP columns a sweep can be judged on
AP_METRICS = tuple(f"ap_{m}_r{p}_iou{i}" for m in ("3d", "bev") for p in (11, 40)
                   for i in ("03", "05"))
#: the paper's headline figure: 3D AP at IoU 0.3 (R40 here; ``ap_3d_r11_iou03`` also reported)
DEFAULT_METRIC = "ap_3d_r40_iou03"
#: verdict of a comparison whose paired differences are all equal (sample sd 0): no t-test
DEGENERATE = "identical differences: no test possible"
VERDICTS = ("gain", "no detectable difference", "loss", "insufficient trials", DEGENERATE)
#: statuses of runs with a result (``skipped``: found finished in the store)
OK_STATUSES = ("ok", "skipped")
#: bootstrap resamples (scipy's default)
N_RESAMPLES = 9999
#: power at which the minimum detectable effect is stated (Cohen 1988, ch. 2: the usual 0.80)
POWER = 0.80
#: the paper's Δ = Sim Pretrain minus Baseline, 3D AP @ IoU 0.3 [AP points], per real-data
#: fraction (source: paper Table 1)
PAPER_DELTA_AP: dict[float, float] = {0.05: 3.3, 0.10: 0.9, 0.25: 3.2, 0.50: 1.2, 1.00: 3.7}
#: [AP points] paired differences whose sample sd is at most this are identical up to float
#: rounding (APs are in [0, 100]; float64 rounding of their difference is ~1e-14)
ZERO_SPREAD_AP = 1e-9
#: simulated sweeps per n in :func:`interval_coverage` (binomial standard error of a 95 %
#: coverage: sqrt(0.95 * 0.05 / 2000) = 0.5 %)
COVERAGE_SWEEPS = 2000
#: bootstrap resamples per simulated sweep in :func:`interval_coverage` (999: the endpoints'
#: resampling error is small beside the 2,000 sweeps' binomial error, and the simulation of one
#: n takes well under a second)
COVERAGE_RESAMPLES = 999
#: seed of :func:`interval_coverage`'s simulation (one seed: the same figures on every run)
COVERAGE_SEED = 20261120
#: simulated sweeps per batch (bounds memory: batch x resamples x n floats)
_COVERAGE_BATCH = 250
#: most trials :func:`trials_to_detect` searches
MAX_TRIALS = 100_000


def _metric_label(metric: str) -> str:
    """``ap_3d_r40_iou03`` -> ``3D AP, R40, IoU 0.3``."""
    _, kind, rp, iou = metric.split("_")
    return f"{kind.upper()} AP, {rp.upper()}, IoU {iou[3]}.{iou[4:]}"


def _bootstrap_kwargs(seed: int) -> dict[str, Any]:
    params = inspect.signature(sps.bootstrap).parameters
    rng = np.random.default_rng(seed)
    return {"rng": rng} if "rng" in params else {"random_state": rng}


def holm_adjust(pvalues: Sequence[float | None]) -> list[float | None]:
    """Holm's step-down adjusted p-values (Holm 1979), None entries left out of the family.

    With the m defined p-values sorted ascending, ``p_adj(i) = max_{j <= i} min(1, (m - j + 1)
    p(j))``; reject where ``p_adj < alpha``. Controls the family-wise error rate under any
    dependence between the tests.
    """
    idx = [i for i, p in enumerate(pvalues) if p is not None and not math.isnan(p)]
    out: list[float | None] = [None] * len(pvalues)
    m = len(idx)
    running = 0.0
    for rank, i in enumerate(sorted(idx, key=lambda i: pvalues[i])):
        running = max(running, min(1.0, (m - rank) * float(pvalues[i])))
        out[i] = running
    return out


# ---------------------------------------------------------------------------------------------
# Power of the paired t-test
# ---------------------------------------------------------------------------------------------
def _check_level(alpha: float, power: float) -> None:
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must lie in (0, 1), got {alpha}")
    if not alpha < power < 1.0:
        raise ValueError(f"power must lie in (alpha, 1) = ({alpha:g}, 1), got {power}")


def paired_t_power(effect_dz: float, n: int, alpha: float) -> float:
    """Power of the two-sided paired t-test with ``n`` pairs at level ``alpha``.

    Parameters
    ----------
    effect_dz : true mean difference over the true sd of the differences (``delta / sigma``,
        dimensionless); its sign does not matter (two-sided).
    n : pairs, >= 2.
    alpha : two-sided significance level.

    Returns
    -------
    float — ``P(T > t_c) + P(T < -t_c)`` for ``T ~ nct(n - 1, effect_dz sqrt(n))`` and
    ``t_c = t.isf(alpha / 2, n - 1)`` (Owen 1965; Cohen 1988 ch. 2). The lower tail is taken as
    ``nct.sf(t_c, df, -nc)`` (the same by symmetry), which scipy evaluates without the NaN its
    ``nct.cdf`` gives far in the tail. ``alpha`` at ``effect_dz = 0``.
    """
    if int(n) < 2:
        raise ValueError(f"a paired t-test needs n >= 2 pairs, got {n}")
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must lie in (0, 1), got {alpha}")
    df = int(n) - 1
    t_c = sps.t.isf(alpha / 2.0, df)
    nc = abs(float(effect_dz)) * math.sqrt(int(n))
    return float(sps.nct.sf(t_c, df, nc) + sps.nct.sf(t_c, df, -nc))


@functools.lru_cache(maxsize=256)
def minimum_detectable_dz(n: int, alpha: float, power: float = POWER) -> float:
    """The standardised effect ``delta / sigma`` that the two-sided paired t-test with ``n``
    pairs at level ``alpha`` detects with probability ``power``: the root of
    ``paired_t_power(dz, n, alpha) = power`` (``scipy.optimize.brentq``; the power rises
    monotonically from ``alpha`` at 0 towards 1).

    Raises
    ------
    ValueError — ``n < 2``, ``alpha`` outside (0, 1) or ``power`` outside (alpha, 1).
    """
    if int(n) < 2:
        raise ValueError(f"a paired t-test needs n >= 2 pairs, got {n}")
    _check_level(alpha, power)
    hi = 1.0
    while paired_t_power(hi, n, alpha) < power:
        hi *= 2.0
        if hi > 1e9:  # pragma: no cover - would need alpha ~ 1e-300 at n = 2
            raise ValueError(f"no effect reaches power {power} at n={n}, alpha={alpha}")
    return float(optimize.brentq(lambda d: paired_t_power(d, n, alpha) - power, 0.0, hi,
                                 xtol=1e-10, rtol=1e-12))


@dataclasses.dataclass(frozen=True)
class MDE:
    """Minimum detectable effect of one paired comparison.

    Attributes
    ----------
    mde : float or None — [AP points] the smallest true mean difference detected with
        ``power`` (``mde_dz x sd``); None where there is none (``note`` says why).
    mde_dz : float or None — the same, over the sd of the differences (dimensionless).
    n : int — pairs.
    sd : float or None — [AP points] sd of the paired differences used (observed, ddof 1).
    alpha : float — the two-sided level of the test.
    power : float — the power it is stated at.
    note : str or None — why there is no MDE (None when there is one).
    """

    mde: float | None
    mde_dz: float | None
    n: int
    sd: float | None
    alpha: float
    power: float
    note: str | None = None


def minimum_detectable_effect(n: int, sd: float | None, alpha: float,
                              power: float = POWER) -> MDE:
    """Minimum detectable effect [AP points] of a paired design with ``n`` pairs whose
    differences have sd ``sd`` [AP points], at two-sided level ``alpha`` and ``power``.

    No MDE (``mde`` None, ``note`` says why) for fewer than 2 pairs (no t-test), an unknown sd,
    or differences without spread (sd <= :data:`ZERO_SPREAD_AP`: the t statistic is 0/0, the
    test undefined, and "every effect is detectable" would be a statement about rounding).
    """
    _check_level(alpha, power)
    n = int(n)
    if n < 2:
        return MDE(None, None, n, sd, alpha, power,
                   f"{n} pair(s): a paired t-test needs at least 2, so there is no detectable "
                   "effect to state")
    if sd is None or not math.isfinite(sd):
        return MDE(None, None, n, None, alpha, power,
                   "the sd of the paired differences is unknown")
    if sd <= ZERO_SPREAD_AP:
        return MDE(None, None, n, float(sd), alpha, power,
                   "the paired differences are identical (sd 0): the t-test is undefined, "
                   "and so is its detectable effect")
    dz = minimum_detectable_dz(n, float(alpha), float(power))
    return MDE(dz * float(sd), dz, n, float(sd), float(alpha), float(power))


@dataclasses.dataclass(frozen=True)
class TrialsNeeded:
    """Trials a paired design needs to detect an effect.

    Attributes
    ----------
    n : int or None — the smallest number of pairs (>= 2) with power >= ``power``; None where
        there is none within :data:`MAX_TRIALS` or it cannot be computed (``note``).
    effect : float or None — [AP points] the effect to detect.
    sd : float or None — [AP points] the sd of the paired differences assumed.
    alpha, power : float — the two-sided level and the power.
    achieved_power : float or None — the power at ``n``.
    note : str or None — why there is no ``n``.
    """

    n: int | None
    effect: float | None
    sd: float | None
    alpha: float
    power: float
    achieved_power: float | None = None
    note: str | None = None


def trials_to_detect(effect: float | None, sd: float | None, alpha: float,
                     power: float = POWER, *, max_n: int = MAX_TRIALS) -> TrialsNeeded:
    """The number of pairs at which the two-sided paired t-test at level ``alpha`` detects a
    true mean difference ``effect`` [AP points] with ``power``, the differences having sd
    ``sd`` [AP points] (:func:`paired_t_power` rises with n; the smallest n is found by
    doubling, then bisection over integers)."""
    _check_level(alpha, power)

    def none(note: str) -> TrialsNeeded:
        return TrialsNeeded(None, effect, sd, alpha, power, None, note)

    if effect is None:
        return none("no effect given")
    if effect == 0:
        return none("a zero effect is never detected (power stays at alpha)")
    if sd is None or not math.isfinite(sd):
        return none("the sd of the paired differences is unknown (fewer than 2 pairs)")
    if sd <= ZERO_SPREAD_AP:
        return none("the paired differences are identical (sd 0): no t-test to plan")
    dz = abs(float(effect)) / float(sd)
    if paired_t_power(dz, 2, alpha) >= power:
        return TrialsNeeded(2, effect, sd, alpha, power, paired_t_power(dz, 2, alpha))
    lo, hi = 2, 4
    while paired_t_power(dz, hi, alpha) < power:
        lo, hi = hi, 2 * hi
        if lo >= max_n:
            return none(f"more than {max_n:,} trials")
    while hi - lo > 1:  # power(lo) < power <= power(hi)
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if paired_t_power(dz, mid, alpha) >= power else (mid, hi)
    if hi > max_n:
        return none(f"more than {max_n:,} trials")
    return TrialsNeeded(hi, effect, sd, alpha, power, paired_t_power(dz, hi, alpha))


def paper_delta(fraction: float) -> float | None:
    """The paper's Δ [AP points] at ``fraction`` (:data:`PAPER_DELTA_AP`), None at a fraction
    Table 1 does not have."""
    for f, d in PAPER_DELTA_AP.items():
        if math.isclose(f, float(fraction), rel_tol=0.0, abs_tol=1e-9):
            return d
    return None


def proportion_improved(k: int, n: int, confidence: float = 0.95,
                        ) -> tuple[float | None, list[float | None]]:
    """Share ``k / n`` of pairs in which the condition beat the baseline, and its
    Clopper–Pearson (exact) interval at ``confidence`` (``scipy.stats.binomtest(k, n)
    .proportion_ci(confidence, method="exact")``). ``(None, [None, None])`` for n = 0."""
    if int(n) == 0:
        return None, [None, None]
    ci = sps.binomtest(int(k), int(n)).proportion_ci(confidence_level=confidence,
                                                      method="exact")
    return int(k) / int(n), [float(ci.low), float(ci.high)]


# ---------------------------------------------------------------------------------------------
# Intervals
# ---------------------------------------------------------------------------------------------
def paired_comparison(
    treated: np.ndarray,
    baseline: np.ndarray,
    alpha: float = 0.05,
    *,
    n_resamples: int = N_RESAMPLES,
    seed: int = 0,
) -> dict[str, np.ndarray]:
    """Paired difference statistics along the last axis (vectorised over leading axes).

    Parameters
    ----------
    treated, baseline : (..., n) — the two conditions' values, paired along the last axis.
    alpha : 1 - confidence level of the intervals.
    n_resamples : bootstrap resamples (0: no bootstrap; its bounds are NaN).
    seed : seed of the bootstrap's generator (reproducible intervals).

    Returns
    -------
    dict of (...) float arrays: ``mean_diff``, ``sd_diff`` (ddof 1), ``t_lo``, ``t_hi``
    (Student-t interval), ``p`` (two-sided paired t-test), ``d_z``, ``boot_lo``, ``boot_hi``
    (BCa bootstrap interval of the mean difference), ``k_improved``, ``flat`` (bool: the
    differences have no spread, sd <= :data:`ZERO_SPREAD_AP`). Where flat, the t statistic is
    0/0: ``p``, the intervals and ``d_z`` are NaN. Needs n >= 2.
    """
    x = np.asarray(treated, dtype=np.float64)
    y = np.asarray(baseline, dtype=np.float64)
    if x.shape != y.shape or x.shape[-1] < 2:
        raise ValueError(f"need equal shapes with >= 2 pairs on the last axis, got {x.shape}, "
                         f"{y.shape}")
    d = x - y
    mean = d.mean(axis=-1)
    sd = d.std(axis=-1, ddof=1)
    flat = sd <= ZERO_SPREAD_AP
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # zero-spread rows, handled below
        res = sps.ttest_rel(x, y, axis=-1)
        ci = res.confidence_interval(1.0 - alpha)
        p = np.where(flat, np.nan, res.pvalue)
        t_lo = np.where(flat, np.nan, ci.low)
        t_hi = np.where(flat, np.nan, ci.high)
        d_z = np.where(flat, np.nan, mean / np.where(flat, 1.0, sd))
    boot_lo = np.full(mean.shape, np.nan)
    boot_hi = np.full(mean.shape, np.nan)
    if n_resamples:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # DegenerateDataWarning on zero-spread rows
            b = sps.bootstrap((d,), np.mean, confidence_level=1.0 - alpha,
                              n_resamples=int(n_resamples), method="BCa", axis=-1,
                              vectorized=True, **_bootstrap_kwargs(seed))
        boot_lo = np.where(flat, np.nan, b.confidence_interval.low)
        boot_hi = np.where(flat, np.nan, b.confidence_interval.high)
    return {"mean_diff": mean, "sd_diff": sd, "t_lo": np.asarray(t_lo), "t_hi": np.asarray(t_hi),
            "p": np.asarray(p, dtype=np.float64), "d_z": np.asarray(d_z, dtype=np.float64),
            "boot_lo": boot_lo, "boot_hi": boot_hi, "k_improved": (d > 0).sum(axis=-1),
            "flat": np.asarray(flat)}


@dataclasses.dataclass(frozen=True)
class Coverage:
    """Measured coverage of the two intervals of :func:`paired_comparison` at one n.

    Attributes
    ----------
    n_pairs : int — pairs per simulated sweep.
    sweeps : int — simulated sweeps.
    confidence : float — nominal level of both intervals.
    t : float — share of sweeps whose Student-t interval covered the true mean difference.
    bootstrap : float — the same for the BCa bootstrap interval.
    resamples : int — bootstrap resamples per sweep.
    seed : int — the simulation's seed.
    """

    n_pairs: int
    sweeps: int
    confidence: float
    t: float
    bootstrap: float
    resamples: int
    seed: int


@functools.lru_cache(maxsize=64)
def interval_coverage(n_pairs: int, alpha: float = 0.05, *, sweeps: int = COVERAGE_SWEEPS,
                      n_resamples: int = COVERAGE_RESAMPLES,
                      seed: int = COVERAGE_SEED) -> Coverage:
    """Coverage of the ``1 - alpha`` t- and BCa bootstrap intervals of the mean paired
    difference with ``n_pairs`` pairs, by simulation (cached per process).

    ``sweeps`` sweeps of ``n_pairs`` differences ~ N(0, 1), seeded: the share whose interval
    holds the true mean 0. Both intervals are affine-equivariant (shifting and scaling the
    differences shifts and scales the interval), so their coverage under normal differences
    depends on n and alpha only, not on the true mean or sd: one simulation per n serves every
    comparison. Batched (:data:`_COVERAGE_BATCH` sweeps at a time) to bound memory.
    """
    n = int(n_pairs)
    if n < 2:
        raise ValueError(f"interval coverage needs n_pairs >= 2, got {n_pairs}")
    rng = np.random.default_rng([int(seed), n])
    d = rng.normal(0.0, 1.0, (int(sweeps), n))
    hit_t = hit_b = 0
    for start in range(0, int(sweeps), _COVERAGE_BATCH):
        chunk = d[start:start + _COVERAGE_BATCH]
        s = paired_comparison(chunk, np.zeros_like(chunk), alpha, n_resamples=n_resamples,
                              seed=int(seed) + start)
        hit_t += int(np.sum((s["t_lo"] <= 0.0) & (0.0 <= s["t_hi"])))
        hit_b += int(np.sum((s["boot_lo"] <= 0.0) & (0.0 <= s["boot_hi"])))
    return Coverage(n, int(sweeps), 1.0 - float(alpha), hit_t / int(sweeps),
                    hit_b / int(sweeps), int(n_resamples), int(seed))


def stats_count_runs(stats: Mapping[str, Any], runs: Sequence[Mapping[str, Any]]) -> bool:
    """Whether a :func:`sweep_statistics` document counts exactly the runs of its conditions
    in ``runs`` (False for a document written before the latest runs finished, or not one)."""
    conds = set(stats.get("conditions") or ())
    try:
        counted = sum(int(c.get("n", 0)) + int(c.get("n_failed", 0)) for c in stats["cells"])
    except (KeyError, TypeError, ValueError, AttributeError):
        return False
    return counted == sum(r.get("condition") in conds for r in runs)


def _num(v: Any) -> float | None:
    """A finite float, or None (JSON has no NaN)."""
    if v is None:
        return None
    f = float(v)
    return f if math.isfinite(f) else None


def as_rows(runs: Iterable[Mapping[str, Any]] | Any) -> list[dict[str, Any]]:
    """Run rows as a list of dicts (from a list of mappings or a pyarrow Table)."""
    if hasattr(runs, "to_pylist"):  # a pyarrow Table
        return list(runs.to_pylist())
    return [dict(r) for r in runs]


def sweep_stats(
    runs: Iterable[Mapping[str, Any]] | Any,
    metric: str = DEFAULT_METRIC,
    *,
    alpha: float = 0.05,
    conditions: Sequence[str] | None = None,
    n_resamples: int = N_RESAMPLES,
    seed: int = 0,
    power: float = POWER,
    primary_fractions: Sequence[float] | None = None,
    primary_condition: str | None = "sim-pretrain",
) -> dict[str, Any]:
    """The sweep's statistics as one JSON-able dict (read by the dashboard and the report).

    Parameters
    ----------
    runs : rows of the ``experiment_runs`` schema (list of dicts or a pyarrow Table); used
        columns: ``condition``, ``fraction``, ``trial``, ``n_real_frames``, ``sim_real_ratio``,
        ``status`` and the metric.
    metric : one of :data:`AP_METRICS` (default the paper's 3D AP at IoU 0.3, R40).
    alpha : family-wise error rate per condition; the intervals are ``1 - alpha``.
    conditions : conditions to report, baseline first (default: those in ``runs``, in
        :data:`~sim2radar.experiment.profiles.CONDITIONS` order).
    n_resamples, seed : bootstrap resamples and generator seed.
    power : power at which the minimum detectable effects are stated.
    primary_fractions : the pooled (primary) endpoint's fractions (default
        :func:`~sim2radar.experiment.profiles.default_primary_fractions` of the runs'
        fractions; those without runs are dropped).
    primary_condition : the condition whose pooled difference is the pre-registered primary
        endpoint (the others' are diagnostics beside it).

    Returns
    -------
    dict::

        {"metric": str, "alpha": float, "conditions": [str], "fractions": [float],
         "cells": [{"condition", "fraction", "n_real_frames", "sim_real_ratio", "n",
                    "n_failed", "mean", "std", "values": [float], "trials": [int]}],
         "comparisons": [{"condition", "fraction", "n_pairs", "mean_diff", "sd_diff",
                          "t_ci": [lo, hi], "bootstrap_ci": [lo, hi], "bootstrap_coverage",
                          "p", "p_holm", "d_z", "k_improved", "p_improved",
                          "p_improved_ci": [lo, hi], "verdict", "mde", "mde_dz",
                          "mde_alpha", "mde_note", "paper_delta", "n_for_paper_delta",
                          "n_for_paper_delta_note", "differences": [float],
                          "trials": [int]}],
         "pooled": [{"condition", "primary": bool, "fractions": [float], "n_pairs",
                     "baseline_mean", "condition_mean", "mean_diff", "sd_diff",
                     "t_ci": [lo, hi], "p", "d_z", "k_improved", "p_improved",
                     "p_improved_ci", "verdict", "mde", "mde_alpha", "mde_note",
                     "differences": [float], "trials": [int]}],
         "primary": {"condition", "fractions"},
         "power": {"power", "sided", "level", "paper_delta": {fraction: Δ}, "source"},
         "notes": [str]}

    ``pooled``: per non-baseline condition, the **primary endpoint**'s form: per trial the mean
    over ``primary_fractions`` of the paired differences (trials complete at every one of them
    only), then the paired t-interval, test and MDE of those per-trial means at ``alpha``
    (one pre-registered test, no family adjustment; the non-primary conditions' pooled
    differences are diagnostics at the same unadjusted level). The per-fraction comparisons are
    secondary; each carries ``t_ci_simultaneous``, the ``1 - alpha / m`` t-interval (Bonferroni
    over its condition's m fractions): it excludes 0 only where the Holm verdict calls a gain
    or loss (Holm rejects all that Bonferroni does; it may call a fraction whose simultaneous
    interval still touches 0).

    ``cells``: one per (condition, fraction), conditions in order then fractions ascending;
    ``std`` is the sample standard deviation (ddof 1); values and trials in trial order.
    ``comparisons``: one per (non-baseline condition, fraction), difference = condition minus
    baseline [AP points]. ``mde`` [AP points] at two-sided level ``mde_alpha`` (alpha over the
    condition's Holm family size) and ``power``; ``n_for_paper_delta`` the pairs that would
    detect ``paper_delta`` (:data:`PAPER_DELTA_AP`) at the same level and the observed sd;
    ``p_improved`` = ``k_improved / n_pairs`` with its Clopper–Pearson ``1 - alpha`` interval;
    ``bootstrap_coverage`` the bootstrap interval's simulated coverage at ``n_pairs``
    (:func:`interval_coverage`). Undefined numbers are None (mean of no runs, std of one,
    intervals, p and MDE of fewer than 2 pairs or of differences without spread); the
    interval lists then hold None, and ``mde_note`` / ``n_for_paper_delta_note`` say why.
    """
    if metric not in AP_METRICS:
        raise ValueError(f"metric must be one of {AP_METRICS}, got {metric!r}")
    _check_level(alpha, power)
    rows = as_rows(runs)
    for i, r in enumerate(rows):
        missing = [k for k in ("condition", "fraction", "trial") if r.get(k) is None]
        if missing:
            raise ValueError(f"run {i}: missing {missing}")
    present = {r["condition"] for r in rows}
    if conditions is None:
        conds = [c for c in CONDITIONS if c in present]
        conds += sorted(present - set(conds))
    else:
        conds = list(conditions)
    if BASELINE in conds:
        conds = [BASELINE] + [c for c in conds if c != BASELINE]
    fractions = sorted({float(r["fraction"]) for r in rows})

    # (condition, fraction) -> trial -> value, and failed trials
    values: dict[tuple[str, float], dict[int, float]] = {}
    failed: dict[tuple[str, float], set[int]] = {}
    meta: dict[tuple[str, float], dict[str, Any]] = {}
    for r in rows:
        key = (str(r["condition"]), float(r["fraction"]))
        trial = int(r["trial"])
        m = meta.setdefault(key, {"n_real_frames": None, "sim_real_ratio": None})
        if m["n_real_frames"] is None and r.get("n_real_frames") is not None:
            m["n_real_frames"] = int(r["n_real_frames"])
        if m["sim_real_ratio"] is None and _num(r.get("sim_real_ratio")) is not None:
            m["sim_real_ratio"] = _num(r["sim_real_ratio"])
        v = _num(r.get(metric))
        if r.get("status", "ok") not in OK_STATUSES or v is None:
            failed.setdefault(key, set()).add(trial)
            continue
        cell = values.setdefault(key, {})
        if trial in cell and not math.isclose(cell[trial], v, rel_tol=0, abs_tol=1e-9):
            raise ValueError(f"two different results for {key[0]} at fraction {key[1]:g}, "
                             f"trial {trial}: {cell[trial]} and {v}")
        cell[trial] = v

    cells = []
    for c in conds:
        for f in fractions:
            vals = values.get((c, f), {})
            trials = sorted(vals)
            arr = np.array([vals[t] for t in trials])
            n_failed = len(failed.get((c, f), set()) - set(vals))
            m = meta.get((c, f), {"n_real_frames": None, "sim_real_ratio": None})
            cells.append({
                "condition": c, "fraction": f, "n_real_frames": m["n_real_frames"],
                "sim_real_ratio": m["sim_real_ratio"], "n": len(trials), "n_failed": n_failed,
                "mean": _num(arr.mean()) if arr.size else None,
                "std": _num(arr.std(ddof=1)) if arr.size > 1 else None,
                "values": [float(v) for v in arr], "trials": trials,
            })

    comparisons = []
    for c in (c for c in conds if c != BASELINE):
        block = []
        for f in fractions:
            base, treat = values.get((BASELINE, f), {}), values.get((c, f), {})
            trials = sorted(set(base) & set(treat))
            d = [treat[t] - base[t] for t in trials]
            k = int(sum(x > 0 for x in d))
            share, share_ci = proportion_improved(k, len(d), 1.0 - alpha)
            comp: dict[str, Any] = {
                "condition": c, "fraction": f, "n_pairs": len(trials),
                "mean_diff": _num(np.mean(d)) if d else None,
                "sd_diff": _num(np.std(d, ddof=1)) if len(d) > 1 else None,
                "t_ci": [None, None], "t_ci_simultaneous": [None, None],
                "bootstrap_ci": [None, None], "bootstrap_coverage": None,
                "p": None, "p_holm": None, "d_z": None, "k_improved": k,
                "p_improved": share, "p_improved_ci": share_ci,
                "verdict": "insufficient trials", "mde": None, "mde_dz": None,
                "mde_alpha": None, "mde_note": None, "paper_delta": paper_delta(f),
                "n_for_paper_delta": None, "n_for_paper_delta_note": None,
                "differences": [float(x) for x in d], "trials": trials,
            }
            if len(trials) >= 2:
                s = paired_comparison(np.array([treat[t] for t in trials]),
                                      np.array([base[t] for t in trials]), alpha,
                                      n_resamples=n_resamples, seed=seed)
                comp.update(
                    mean_diff=_num(s["mean_diff"]), sd_diff=_num(s["sd_diff"]),
                    t_ci=[_num(s["t_lo"]), _num(s["t_hi"])],
                    bootstrap_ci=[_num(s["boot_lo"]), _num(s["boot_hi"])], p=_num(s["p"]),
                    d_z=_num(s["d_z"]),
                )
                if bool(s["flat"]):
                    comp["verdict"] = DEGENERATE
                elif n_resamples:
                    comp["bootstrap_coverage"] = interval_coverage(len(trials), alpha).bootstrap
            block.append(comp)
        family = holm_adjust([b["p"] for b in block])
        m_family = sum(p is not None for p in family)
        for comp, p_adj in zip(block, family, strict=True):
            comp["p_holm"] = p_adj
            if p_adj is not None:
                if p_adj < alpha and comp["mean_diff"]:
                    comp["verdict"] = "gain" if comp["mean_diff"] > 0 else "loss"
                else:
                    comp["verdict"] = "no detectable difference"
            level = alpha / m_family if m_family else alpha
            mde = minimum_detectable_effect(comp["n_pairs"], comp["sd_diff"], level, power)
            need = trials_to_detect(comp["paper_delta"], comp["sd_diff"], level, power)
            if comp["paper_delta"] is None:
                need = dataclasses.replace(need, note="the paper's Table 1 has no Δ at this "
                                                      "fraction")
            comp.update(mde=_num(mde.mde), mde_dz=_num(mde.mde_dz),
                        mde_alpha=float(level) if m_family else None, mde_note=mde.note,
                        n_for_paper_delta=need.n, n_for_paper_delta_note=need.note)
            if p_adj is not None:
                f = float(comp["fraction"])
                trials = comp["trials"]
                sim = paired_comparison(np.array([values[(c, f)][t] for t in trials]),
                                        np.array([values[(BASELINE, f)][t] for t in trials]),
                                        level, n_resamples=0)
                comp["t_ci_simultaneous"] = [_num(sim["t_lo"]), _num(sim["t_hi"])]
        comparisons += block

    primary = [f for f in (default_primary_fractions(fractions) if primary_fractions is None
                           else sorted(float(f) for f in primary_fractions)) if f in fractions]
    pooled = [_pooled(c, primary, values, alpha, power, c == primary_condition)
              for c in conds if c != BASELINE] if primary else []

    power_doc = {"power": float(power), "sided": "two-sided",
                 "level": "alpha / m, m = the condition's Holm family size (fractions with a "
                          "p-value): Holm's first step, at which a fraction is called whatever "
                          "the others show",
                 "paper_delta": {f"{f:g}": d for f, d in PAPER_DELTA_AP.items()},
                 "source": "paper Table 1 (Sim Pretrain minus Baseline, 3D AP @ IoU 0.3)"}
    return {"metric": metric, "alpha": float(alpha), "conditions": conds,
            "fractions": fractions, "cells": cells, "comparisons": comparisons,
            "pooled": pooled, "primary": {"condition": primary_condition, "fractions": primary},
            "power": power_doc,
            "notes": _pooled_notes(primary, primary_condition, alpha, power, pooled)
            + _notes(metric, alpha, power, cells, comparisons, len(fractions), n_resamples)}


def _pooled(condition: str, fractions: Sequence[float],
            values: Mapping[tuple[str, float], Mapping[int, float]], alpha: float, power: float,
            primary: bool) -> dict[str, Any]:
    """One condition's pooled endpoint (see :func:`sweep_stats`)."""
    def complete(c: str) -> set[int]:
        sets = [set(values.get((c, f), {})) for f in fractions]
        return set.intersection(*sets) if sets else set()

    trials = sorted(complete(BASELINE) & complete(condition))
    base = np.array([np.mean([values[(BASELINE, f)][t] for f in fractions]) for t in trials])
    treat = np.array([np.mean([values[(condition, f)][t] for f in fractions]) for t in trials])
    d = treat - base
    k = int(np.sum(d > 0))
    share, share_ci = proportion_improved(k, len(d), 1.0 - alpha)
    out: dict[str, Any] = {
        "condition": condition, "primary": bool(primary), "fractions": list(fractions),
        "n_pairs": len(trials), "baseline_mean": _num(base.mean()) if len(d) else None,
        "condition_mean": _num(treat.mean()) if len(d) else None,
        "mean_diff": _num(d.mean()) if len(d) else None,
        "sd_diff": _num(d.std(ddof=1)) if len(d) > 1 else None, "t_ci": [None, None],
        "p": None, "d_z": None, "k_improved": k, "p_improved": share, "p_improved_ci": share_ci,
        "verdict": "insufficient trials", "mde": None, "mde_alpha": float(alpha),
        "mde_note": None, "differences": [float(x) for x in d], "trials": trials,
    }
    if len(d) >= 2:
        s = paired_comparison(treat, base, alpha, n_resamples=0)
        out.update(t_ci=[_num(s["t_lo"]), _num(s["t_hi"])], p=_num(s["p"]), d_z=_num(s["d_z"]))
        if bool(s["flat"]):
            out["verdict"] = DEGENERATE
        else:
            out["verdict"] = ("no detectable difference" if out["p"] >= alpha
                              else "gain" if out["mean_diff"] > 0 else "loss")
    mde = minimum_detectable_effect(len(d), out["sd_diff"], alpha, power)
    out.update(mde=_num(mde.mde), mde_note=mde.note)
    return out


def _pooled_notes(fractions: Sequence[float], condition: str | None, alpha: float,
                  power: float, pooled: Sequence[Mapping[str, Any]]) -> list[str]:
    if not pooled:
        return []
    which = ", ".join(_pct(f) for f in fractions)
    return [
        f"Primary endpoint (pre-registered): the mean paired difference pooled over {which}: "
        f"per trial the mean of its paired differences at those fractions (trials complete at "
        f"all of them), then the {100 * (1 - alpha):g} % Student-t interval and paired t-test "
        f"of those per-trial means at alpha = {alpha:g}, one test, no family adjustment; its "
        f"MDE at {100 * power:g} % power from their observed sd. "
        + (f"The primary comparison is {condition} vs baseline; the other conditions' pooled "
           "differences are diagnostics at the same unadjusted level, not further tests of "
           "the primary question." if condition else ""),
        "Secondary: the per-fraction comparisons below, Holm-adjusted within each condition. "
        "Their 'simultaneous' interval is the 1 - alpha / m Student-t interval (Bonferroni over "
        "the condition's m fractions): where it excludes 0, Holm calls the fraction too; the "
        "plain interval beside it is the unadjusted per-fraction interval, which may exclude 0 "
        "where the adjusted test does not.",
    ]


def sweep_statistics(doc: SweepDocument, rows: Iterable[Mapping[str, Any]] | Any,
                     pretrainings: Sequence[Mapping[str, Any]] = (), *,
                     conditions: Sequence[str] | None = None,
                     n_resamples: int = N_RESAMPLES) -> dict[str, Any]:
    """The statistics of a sweep (``stats.json``) from its ``sweep.json`` document
    (:class:`~sim2radar.experiment.documents.SweepDocument`), its runs' rows and its
    pre-trainings' rows: :func:`sweep_stats` on the document's metric (default
    :data:`DEFAULT_METRIC`) with the profile's primary endpoint, and the pre-training table
    (:func:`~sim2radar.experiment.learnability.pretraining_table`) under ``pretrainings``."""
    from sim2radar.experiment.learnability import pretraining_table

    rows = as_rows(rows)
    profile = dict(doc.profile)
    conditions = list(conditions if conditions is not None else doc.conditions or
                      dict.fromkeys(str(r["condition"]) for r in rows))
    fractions = profile.get("fractions") or doc.fractions
    primary = profile.get("primary_fractions") or (
        default_primary_fractions(fractions) if fractions else None)
    metric = doc.metric if "metric" in doc.model_fields_set else DEFAULT_METRIC
    stats = sweep_stats(rows, metric, conditions=conditions, primary_fractions=primary,
                        primary_condition=profile.get("primary_condition", "sim-pretrain"),
                        n_resamples=n_resamples)
    stats["pretrainings"] = pretraining_table(
        pretrainings, profile.get("learnability_thresholds"),
        [c for c in conditions if CONDITIONS.get(c) and CONDITIONS[c].sim_role])
    return stats


def _pct(fraction: float) -> str:
    return f"{100 * fraction:g} %"


def _notes(metric: str, alpha: float, power: float, cells: list[dict], comparisons: list[dict],
           n_fractions: int, n_resamples: int) -> list[str]:
    level = f"{100 * (1 - alpha):g} %"
    notes = [
        f"Metric: {metric} ({_metric_label(metric)}, KITTI devkit thresholds). Cells: mean ± "
        "sample standard deviation (ddof = 1) over trials.",
        "Comparisons are paired by trial: a trial's seed gives every condition the same real "
        "subset, head initialisation and data order, so only the encoder's initialisation "
        "differs. A pair exists only where both runs finished. Difference = condition minus "
        "baseline, in AP points.",
        f"Primary: the {level} Student-t interval of the mean paired difference and the paired "
        f"t-test (scipy.stats.ttest_rel), Holm-adjusted across the {n_fractions} fraction(s) "
        f"of each condition. Verdict 'gain' / 'loss' when the Holm-adjusted p < {alpha:g}, "
        "otherwise 'no detectable difference', which is not evidence of no effect: with few "
        "trials only differences several times their trial-to-trial spread are detectable.",
        f"MDE: the smallest true mean difference the two-sided paired t-test detects with "
        f"{100 * power:g} % power at the comparison's n and the observed sd of its paired "
        "differences (noncentral t, scipy.stats.nct; Owen 1965), at level alpha / m with m "
        "the condition's Holm family size: the level at which Holm's procedure calls a "
        "fraction whatever the other fractions show, so the MDE is one the verdict is sure "
        "to reach. A true effect smaller than the MDE is more likely than not to be missed. "
        "The observed sd is itself uncertain with few pairs, and so is the MDE.",
        "Trials for the paper's Δ: the pairs that would detect the paper's Table 1 difference "
        f"at that fraction ({', '.join(f'{d:+.1f} at {_pct(f)}' for f, d in PAPER_DELTA_AP.items())}"
        f" AP points) with {100 * power:g} % power at the same level, if the paired differences "
        "kept the observed sd.",
        "d_z = mean(d) / sd(d), the paired effect size; 'k/n' = trials in which the condition "
        f"beat the baseline, P(improved) = k/n with its {level} Clopper–Pearson interval "
        "(scipy.stats.binomtest, exact: it never covers less than the nominal level, which "
        "Wilson's interval does at a few pairs).",
    ]
    ns = sorted({c["n_pairs"] for c in comparisons
                 if c["n_pairs"] >= 2 and c["bootstrap_coverage"] is not None})
    if n_resamples and ns:
        covs = [interval_coverage(n, alpha) for n in ns]
        what = "; ".join(f"{100 * c.bootstrap:.0f} % with {c.n_pairs} pairs (t-interval "
                         f"{100 * c.t:.0f} %)" for c in covs)
        anti = any(c.bootstrap < c.confidence - 0.02 for c in covs)
        notes.append(
            f"The bootstrap interval (scipy.stats.bootstrap, BCa, {n_resamples:,} resamples of "
            f"the paired differences) is shown for reference only; conclusions rest on the "
            f"t-interval. In {COVERAGE_SWEEPS:,} simulated sweeps of normal paired differences "
            f"(seed {COVERAGE_SEED}) its nominal {level} interval covered the true mean "
            f"difference {what}"
            + (": it is anti-conservative at this sweep's n." if anti else "."))
    n_pairs = [c["n_pairs"] for c in comparisons if c["n_pairs"] >= 1]
    if n_pairs:
        n = max(n_pairs)
        notes.append(
            f"With {n} pairs a sign test or Wilcoxon signed-rank test cannot give a two-sided p "
            f"below 2/2^{n} = {2 * 0.5 ** n:.4g}, however consistent the difference"
            + (", so neither could reach p < 0.05" if 2 * 0.5 ** n >= 0.05 else "")
            + "; the paired t-test is used.")
    n_failed = sum(c["n_failed"] for c in cells)
    if n_failed:
        where = ", ".join(f"{c['condition']} at {100 * c['fraction']:g} % ({c['n_failed']})"
                          for c in cells if c["n_failed"])
        notes.append(f"{n_failed} failed run(s) excluded: {where}. Their partner runs enter "
                     "the cell means but not the paired comparisons.")
    flat = [c for c in comparisons if c["verdict"] == DEGENERATE]
    if flat:
        where = ", ".join(f"{c['condition']} at {_pct(c['fraction'])} (every pair "
                          f"{c['mean_diff']:+.3g})" for c in flat)
        notes.append(f"{len(flat)} comparison(s) have identical paired differences: {where}. "
                     "Their spread is 0, so the t statistic is 0/0: no p-value, interval, MDE "
                     f"or verdict ('{DEGENERATE}'), and they leave the Holm family. Identical "
                     "differences usually mean the conditions did not differ as intended (e.g. "
                     "the encoder was not loaded) or the test set is too small to move AP.")
    short = [c for c in comparisons if c["verdict"] == "insufficient trials"]
    if short:
        notes.append(f"{len(short)} comparison(s) have fewer than 2 complete pairs: no "
                     "interval, test, MDE or verdict.")
    return notes
