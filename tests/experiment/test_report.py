"""The Markdown report and the artifact rows: Table 1's layout and formatting (with the MDE,
P(improved) and the trials the paper's Δ needs), every trial's value, failed runs, notes, the
sentence on what the sweep could detect, and the real domain's line (proxy, measured,
undeclared, another declared domain)."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.experiment.report import (
    detectability_sentences,
    domain_kind,
    domain_line,
    results_markdown,
    results_table_rows,
)
from sim2radar.experiment.stats import DEGENERATE, sweep_stats

FRACTIONS = (0.05, 0.10, 0.25, 0.50, 1.00)
N_REAL = (18, 37, 92, 185, 371)


def _runs(conditions=("baseline", "sim-pretrain"), trials=5, gain=3.0, sd=0.5):
    rng = np.random.default_rng(0)
    rows = []
    for f, n in zip(FRACTIONS, N_REAL, strict=True):
        for t in range(trials):
            base = 10 + 50 * f + rng.normal(0, 3)
            for i, c in enumerate(conditions):
                rows.append({"condition": c, "fraction": f, "trial": t, "n_real_frames": n,
                             "sim_real_ratio": None if c == "baseline" else 270 / n,
                             "ap_3d_r40_iou03": base + gain * i + rng.normal(0, sd),
                             "status": "ok", "error": "", "wall_time_s": 60.0,
                             "device": "cpu"})
    return rows


def test_table_rows_match_table_1_layout():
    rows = results_table_rows(sweep_stats(_runs()))
    assert len(rows) == 5
    assert list(rows[0]) == ["condition", "real data", "N", "Sim:Real", "baseline",
                             "condition AP", "Δ", "95 % CI", "simultaneous CI", "MDE",
                             "p (Holm)", "d_z", "k/n",
                             "P(improved)", "verdict", "paper Δ (trials)", "bootstrap CI"]
    # N and Sim:Real as in the paper's Table 1 (270 sim frames)
    assert [r["N"] for r in rows] == ["18", "37", "92", "185", "371"]
    assert [r["Sim:Real"] for r in rows] == ["15:1", "7.3:1", "2.9:1", "1.5:1", "0.7:1"]
    assert [r["real data"] for r in rows] == ["5 %", "10 %", "25 %", "50 %", "100 %"]
    assert all(r["Δ"].startswith("+") and r["verdict"] == "gain" and r["k/n"] == "5/5"
               for r in rows)
    mean, std = rows[0]["baseline"].split(" ± ")
    assert float(mean) == pytest.approx(12.9, abs=3) and float(std) > 0


def test_markdown_report():
    runs = _runs(("baseline", "sim-pretrain", "sim-gt-pretrain"))
    runs[1].update(status="failed", ap_3d_r40_iou03=None,
                   error="NonFiniteLoss: fine-tuning in /x: training loss became nan at epoch 3")
    stats = sweep_stats(runs)
    md = results_markdown(stats, runs, title="Demo sweep",
                          real_domain_label="proxy-real (reference radar simulation)")
    assert md.startswith("# Demo sweep")
    # one Table 1 block per non-baseline condition
    assert ("## Sim Pretrain vs Baseline per fraction (secondary, Holm-adjusted)" in md
            and "## Sim-GT Pretrain vs Baseline per fraction" in md)
    assert ("| Real Data | N | Sim:Real | Baseline | Sim Pretrain | Δ [95 % CI, unadjusted] | "
            "simultaneous CI | MDE | p (Holm) | d_z | k/n | P(improved) | Verdict | "
            "Paper Δ (trials) |") in md
    # the primary endpoint first: the pooled Δ over 5/10/25 %, sim-pretrain the primary row
    primary = next(c for c in stats["pooled"] if c["primary"])
    assert primary["condition"] == "sim-pretrain" and primary["fractions"] == [0.05, 0.1, 0.25]
    assert md.index("## Primary endpoint") < md.index("## Sim Pretrain vs Baseline per")
    lo, hi = primary["t_ci"]
    assert (f"| Sim Pretrain | **primary** | {primary['n_pairs']} | "
            f"{primary['baseline_mean']:.1f} | {primary['condition_mean']:.1f} | "
            f"{primary['mean_diff']:+.1f} [{lo:+.1f}, {hi:+.1f}] |") in md
    assert "| Sim-GT Pretrain | diagnostic |" in md
    assert "| 5 % | 18 | 15:1 |" in md
    # every trial's value of every cell
    for cell in stats["cells"]:
        for v in cell["values"]:
            assert f"| {v:.1f} " in md
    assert "| trial 0 | trial 1 | trial 2 | trial 3 | trial 4 | mean ± std | failed |" in md
    # the failed run, its error and the notes
    assert "sim-pretrain at 5 %, trial 0: NonFiniteLoss" in md
    for note in stats["notes"]:
        assert note in md
    # the proxy disclaimer, at the top and the bottom
    line = ("**real = proxy-real (reference radar simulation)**: a stand-in for measured radar. "
            "These results are not claims about measured radar.")
    assert md.count(line) == 2
    measured = results_markdown(stats, [], title="IFR", real_domain_label="IFR (measured)")
    assert "not claims about measured radar" not in measured
    assert "real = IFR (measured) (measured radar)." in measured
    assert "## Runs" not in measured  # no run rows given
    # the MDE beside every Δ and verdict, and the sentence on what the sweep could detect
    for comp in stats["comparisons"]:
        assert f"| {comp['mde']:.1f} |" in md
    for sentence in detectability_sentences(stats):
        assert f"- {sentence}" in md


def test_insufficient_trials_render_as_dashes():
    rows = results_table_rows(sweep_stats(_runs(trials=1)))
    assert all(r["95 % CI"] == "—" and r["p (Holm)"] == "—" and r["d_z"] == "—"
               and r["verdict"] == "insufficient trials" and r["k/n"] in ("0/1", "1/1")
               and r["MDE"] == "— (< 2 pairs)" for r in rows)
    assert all(" ± " not in r["baseline"] for r in rows)  # one value: no std


def test_table_shows_mde_p_improved_and_the_trials_for_the_papers_delta():
    stats = sweep_stats(_runs(trials=3, gain=1.0, sd=2.0))
    rows = results_table_rows(stats)
    for row, comp in zip(rows, stats["comparisons"], strict=True):
        assert row["MDE"] == f"{comp['mde']:.1f}"
        k, n = comp["k_improved"], comp["n_pairs"]
        lo, hi = comp["p_improved_ci"]
        assert row["P(improved)"] == f"{100 * k / n:.0f} % [{100 * lo:.0f}, {100 * hi:.0f}]"
        assert row["paper Δ (trials)"] == (f"{comp['paper_delta']:+.1f} "
                                           f"({comp['n_for_paper_delta']:,})")
        assert row["bootstrap CI"].endswith(f"({100 * comp['bootstrap_coverage']:.0f} % cov.)")
    # a degenerate comparison: its own verdict and the reason for no MDE
    runs = _runs(trials=3, sd=0.0)
    flat = results_table_rows(sweep_stats(runs))
    assert all(r["verdict"] == DEGENERATE and r["MDE"] == "— (sd 0)" and r["p (Holm)"] == "—"
               for r in flat)
    # a stats.json written before the MDE existed still renders (dashes)
    old = sweep_stats(_runs(trials=3))
    for comp in old["comparisons"]:
        for key in ("mde", "p_improved", "p_improved_ci", "paper_delta", "n_for_paper_delta",
                    "bootstrap_coverage"):
            comp.pop(key)
    assert all(r["MDE"] == "—" and r["P(improved)"] == "—" for r in results_table_rows(old))
    assert detectability_sentences(old) == []


def test_detectability_sentence_is_computed_from_the_mde_and_the_papers_effects():
    # 3 noisy trials: every MDE above the paper's effects
    weak = sweep_stats(_runs(trials=3, gain=1.0, sd=3.0))
    (sentence,) = detectability_sentences(weak)
    mdes = [c["mde"] for c in weak["comparisons"]]
    assert sentence.startswith("Sim Pretrain vs Baseline: with 3 trials per fraction this "
                               "sweep could detect gains of ≥ ")
    assert f"≥ {min(mdes):.1f} AP points" in sentence and f"≥ {max(mdes):.1f}" in sentence
    assert "the paper's effects (+0.9 to +3.7) are below that at every fraction" in sentence
    needed = [c["n_for_paper_delta"] for c in weak["comparisons"]]
    assert f"would take {min(needed):,} to {max(needed):,} trials per fraction" in sentence
    # 20 precise trials: every paper effect at or above the MDE
    strong = sweep_stats(_runs(trials=20, gain=3.0, sd=0.3))
    (sentence,) = detectability_sentences(strong)
    assert "with 20 trials per fraction" in sentence
    assert "are at or above it at every fraction" in sentence and "would take" not in sentence
    # in between: named fractions on each side
    rows = _runs(trials=5, gain=2.0, sd=0.3)
    for r in rows:  # noisy differences at 10 % only
        if r["fraction"] == 0.10 and r["condition"] == "sim-pretrain":
            r["ap_3d_r40_iou03"] += (-1) ** r["trial"] * 6.0
    (sentence,) = detectability_sentences(sweep_stats(rows))
    assert "are below it at 10 % and at or above it at 5 %, 25 %, 50 %, 100 %" in sentence
    # nothing to say with one trial
    (sentence,) = detectability_sentences(sweep_stats(_runs(trials=1)))
    assert "cannot say what it could have detected" in sentence


@pytest.mark.parametrize("label,proxy,kind", [
    ("proxy-real (reference radar simulation)", None, "proxy"),
    ("anything", True, "proxy"),
    ("measured", False, "measured"),
    ("IFR (measured)", None, "measured"),
    ("undeclared", False, "undeclared"),
    ("", None, "undeclared"),
    ("synthetic (detect-demo-data)", False, "declared"),
])
def test_domain_kinds_and_lines(label, proxy, kind):
    assert domain_kind(label, proxy) == kind
    line = domain_line(label, proxy)
    assert ("(measured radar)." in line) == (kind == "measured")
    if kind != "measured":
        assert "not" in line and "measured radar" in line


def test_an_undeclared_real_domain_is_not_called_measured():
    """The audit's case: tasks pass the real dataset's domain; one without a declared domain
    read 'real = measured (measured radar)'."""
    stats = sweep_stats(_runs(trials=2))
    md = results_markdown(stats, [], title="t", real_domain_label="undeclared", proxy=False)
    assert "measured radar)." not in md and md.count("**real = undeclared**") == 2
    demo = results_markdown(stats, [], title="t", real_domain_label="synthetic (detect-demo-data)",
                            proxy=False)
    assert "**real = synthetic (detect-demo-data)**" in demo and "(measured radar)" not in demo
