"""The Markdown report and the artifact rows: Table 1's layout and formatting, every trial's
value, failed runs, notes, and the proxy disclaimer."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.experiment.report import results_markdown, results_table_rows
from sim2radar.experiment.stats import sweep_stats

FRACTIONS = (0.05, 0.10, 0.25, 0.50, 1.00)
N_REAL = (18, 37, 92, 185, 371)


def _runs(conditions=("baseline", "sim-pretrain"), trials=5):
    rng = np.random.default_rng(0)
    rows = []
    for f, n in zip(FRACTIONS, N_REAL, strict=True):
        for t in range(trials):
            base = 10 + 50 * f + rng.normal(0, 3)
            for i, c in enumerate(conditions):
                rows.append({"condition": c, "fraction": f, "trial": t, "n_real_frames": n,
                             "sim_real_ratio": None if c == "baseline" else 270 / n,
                             "ap_3d_r40_iou03": base + 3 * i + rng.normal(0, 0.5),
                             "status": "ok", "error": "", "wall_time_s": 60.0,
                             "device": "cpu"})
    return rows


def test_table_rows_match_table_1_layout():
    rows = results_table_rows(sweep_stats(_runs()))
    assert len(rows) == 5
    assert list(rows[0]) == ["condition", "real data", "N", "Sim:Real", "baseline",
                             "condition AP", "Δ", "95 % CI", "p (Holm)", "d_z", "k/n", "verdict",
                             "bootstrap CI"]
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
    assert "## Sim Pretrain vs Baseline" in md and "## Sim-GT Pretrain vs Baseline" in md
    assert "| Real Data | N | Sim:Real | Baseline | Sim Pretrain | Δ [95 % CI] | p (Holm) |" in md
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


def test_insufficient_trials_render_as_dashes():
    rows = results_table_rows(sweep_stats(_runs(trials=1)))
    assert all(r["95 % CI"] == "—" and r["p (Holm)"] == "—" and r["d_z"] == "—"
               and r["verdict"] == "insufficient trials" and r["k/n"] in ("0/1", "1/1")
               for r in rows)
    assert all(" ± " not in r["baseline"] for r in rows)  # one value: no std
