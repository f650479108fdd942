"""The sweep dashboard without a browser: what the page shows for a constructed sweep (cell
means, paired differences with their simultaneous interval, the MDE and P(improved) per cell
and the sentence on what the sweep could detect, the pooled primary endpoint, the
pre-trainings' checks and loss curves, trial points, runs with their folders, progress, banner
per real domain), that the page is self-contained, that partial, old and broken sweep folders
behave, the CLI, and the live server's endpoints. The gap section: test_dashboard_gap.py; the
runs' own views: test_dashboard_runs.py; two sweeps compared: test_dashboard_compare.py.

``make_sweep`` / ``append_run`` / ``pretrain_row`` / ``write_pretrainings`` are shared with
test_dashboard_browser.py.
"""

from __future__ import annotations

import json
import os
import re
import select
import signal
import struct
import subprocess
import sys
import time
import urllib.error
import urllib.request
import zlib
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from scipy import stats as sps

from sim2radar.experiment.dashboard import (
    SweepFolderError,
    dashboard_data,
    load_sweep,
    render_html,
    run_folder,
    serve_dashboard,
    write_dashboard,
)
from sim2radar.experiment.report import detectability_sentences
from sim2radar.storage import get_schema

REPO = Path(__file__).resolve().parents[2]
PROXY = "proxy-real (reference radar simulation)"
FRACTIONS = (0.1, 0.5, 1.0)
TRIALS = 3
N_TRAIN = 40


# ------------------------------------------------------------------------------ sweep folders
def ap_of(condition: str, fraction: float, trial: int) -> float:
    """The constructed sweep's AP: baseline 21 + 40 f ± 1 (trial - 1); sim-pretrain adds
    3 + 0.5 trial, so its paired differences are 3.0, 3.5, 4.0 at every fraction."""
    base = 20.0 + 40.0 * fraction + trial
    return base if condition == "baseline" else base + 3.0 + 0.5 * trial


def run_row(condition: str, fraction: float, trial: int, *, status: str = "ok",
            error: str = "", epochs: int = 4) -> dict:
    """One experiment_runs row of the constructed sweep."""
    n_real = max(1, round(N_TRAIN * fraction))
    n_sim = 0 if condition == "baseline" else 120
    ok = status != "failed"
    ap = ap_of(condition, fraction, trial) if ok else None
    row = {
        "sweep": "t", "run_key": f"{condition}-{fraction:g}-{trial}-" + "0" * 40,
        "condition": condition, "fraction": fraction, "n_real_frames": n_real,
        "n_sim_frames": n_sim, "sim_real_ratio": None if n_sim == 0 else n_sim / n_real,
        "trial": trial, "seed": 1000 + trial,
        "epochs": epochs, "steps": 10 * epochs if ok else 0,
        "history_epoch": list(range(1, epochs + 1)) if ok else [],
        "history_loss": [2.0 / e for e in range(1, epochs + 1)] if ok else [],
        "history_val_epoch": [2, 4] if ok else [],
        "history_val_ap": [0.5 * ap, ap] if ok else [],
        "wall_time_s": 12.5 if ok else 0.0, "device": "cpu" if ok else "",
        "checkpoint": f"t/runs/{condition}-{fraction:g}-{trial}/last.pt" if ok else "",
        "pretrain_key": None if n_sim == 0 else f"pre-{trial}",
        "status": status, "error": error, "finished_at": "2026-11-20T10:00:00+00:00",
    }
    for m in ("3d", "bev"):
        for p in ("11", "40"):
            for i in ("03", "05"):
                row[f"ap_{m}_r{p}_iou{i}"] = None if ap is None else ap - (i == "05") * 10.0
    return row


def write_runs(folder: Path, rows: list[dict]) -> None:
    """runs.parquet, validated against the declared schema and replaced atomically (as the
    sweep flow does)."""
    schema = get_schema("experiment_runs")
    table = schema.validate(pa.Table.from_pylist(rows, schema=schema.schema))
    tmp = folder / ".runs.parquet.tmp"
    pq.write_table(table, tmp)
    os.replace(tmp, folder / "runs.parquet")


def append_run(folder: Path, row: dict) -> int:
    """Add one run to runs.parquet (atomic rewrite); returns the new number of runs."""
    rows = pq.read_table(folder / "runs.parquet").to_pylist() + [row]
    write_runs(folder, rows)
    return len(rows)


def pretrain_row(trial: int | None, *, heldout: float | None = 30.0,
                 zero_shot: float | None = 5.0, train: float | None = 60.0,
                 conditions=("sim-pretrain",), role: str = "sim", status: str = "ok",
                 error: str = "", loss=(3.0, 2.0, 1.5)) -> dict:
    """One experiment_pretrain row (a pre-training of the constructed sweep and its check);
    a failed one has no AP and the loss of the epochs it made."""
    ok = status != "failed"
    row = {
        "sweep": "t", "pretrain_key": f"pre-{role}-{trial}-" + "0" * 40,
        "pretrain_id": f"pretrain-{role}-t{trial}", "sim_role": role,
        "conditions": list(conditions), "trial": trial, "fraction": None, "seed": 7 + (trial or 0),
        "n_sim_frames": 100, "holdout_split": "val", "n_heldout_frames": 20,
        "n_real_val_frames": 10, "epochs": len(loss), "steps": 13 * len(loss),
        "history_epoch": list(range(1, len(loss) + 1)), "history_loss": list(loss),
        "wall_time_s": 30.0, "check_s": 2.0,
        "checkpoint": f"t/pretrain/{role}-{trial}/last.pt" if ok else "",
        "status": status, "error": error, "finished_at": "2026-11-20T09:30:00+00:00",
    }
    for where, ap in (("train", train), ("heldout", heldout), ("zero_shot", zero_shot)):
        for m in ("3d", "bev"):
            row[f"{where}_ap_{m}_r40_iou03"] = ap if ok and ap is not None else None
    return row


def write_pretrainings(folder: Path, rows: list[dict]) -> None:
    """pretrainings.parquet, validated against the declared experiment_pretrain schema."""
    schema = get_schema("experiment_pretrain")
    pq.write_table(schema.validate(pa.Table.from_pylist(rows, schema=schema.schema)),
                   folder / "pretrainings.parquet")


def edit_sweep_json(folder: Path, **profile) -> None:
    """Add ``profile`` fields to the sweep.json profile (as the sweep flow writes them)."""
    doc = json.loads((folder / "sweep.json").read_text())
    doc["profile"].update(profile)
    (folder / "sweep.json").write_text(json.dumps(doc))


def png_bytes(width: int = 64, height: int = 48) -> bytes:
    """A valid RGB PNG (PNG spec: signature, IHDR, one IDAT, IEND) with a colour gradient."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    rows = b"".join(b"\x00" + bytes(v for x in range(width)
                                    for v in (x * 4 % 256, y * 5 % 256, 128))
                    for y in range(height))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(rows))
            + chunk(b"IEND", b""))


def make_sweep(folder: Path, *, conditions=("baseline", "sim-pretrain"),
               fractions=FRACTIONS, trials=TRIALS, failed=(("sim-pretrain", 0.5, 2),),
               ran=None, proxy: bool = True, sweep_json: bool = True,
               extras: bool = True, domain: str | None = None) -> Path:
    """A sweep folder like the sweep flow writes: runs.parquet (every run of ``ran``
    conditions, ``failed`` ones failed), sweep.json (real domain ``domain``, default the
    proxy's or "measured" by ``proxy``) and, with ``extras``, progress.json, generation.json
    and gap/ with gap.json and two PNGs. No stats.json."""
    folder.mkdir(parents=True, exist_ok=True)
    ran = conditions if ran is None else ran
    rows = [run_row(c, f, t, status="failed" if (c, f, t) in failed else "ok",
                    error="RuntimeError: diverged </script><b>x</b>" if (c, f, t) in failed
                    else "")
            for c in ran for f in fractions for t in range(trials)]
    write_runs(folder, rows)
    n_runs = len(conditions) * len(fractions) * trials
    if sweep_json:
        domain = domain or (PROXY if proxy else "measured")
        sweep = {
            "name": folder.name, "profile": {"name": "smoke", "trials": trials},
            "conditions": list(conditions), "fractions": list(fractions), "trials": trials,
            "metric": "ap_3d_r40_iou03",
            "datasets": {"sim": {"role": "sim", "path": "/data/sim", "key": "k" * 16,
                                 "domain": "measured", "n_frames": 120,
                                 "splits": {"train": 100, "val": 20}},
                         "real": {"role": "real", "path": "/data/real", "key": "r" * 16,
                                  "domain": domain, "n_frames": 60,
                                  "splits": {"train": N_TRAIN, "val": 10, "test": 10}}},
            "real_domain": domain, "real_is_proxy": proxy, "n_runs": n_runs,
            "provenance": {"versions": {"python": "3.11.2", "torch": "2.13.0"},
                           "code": {"stage_version": 1, "sim2radar": "0.1.0"},
                           "configs": {"finetune": {"model": {"name": "pointpillars"}}}},
            "settings": {"profile": {"name": "smoke", "trials": trials}},
            "settings_digest": "0123456789abcdef0123",
            "settings_fixed_at": "2026-11-20T08:00:00+00:00",
            "created_at": "2026-11-20T09:00:00+00:00",
        }
        (folder / "sweep.json").write_text(json.dumps(sweep))
    if extras:
        (folder / "progress.json").write_text(json.dumps({
            "total_runs": n_runs, "finished": len(rows),
            "failed": sum(r["status"] == "failed" for r in rows),
            "running": ["sim-pretrain 100 % t2"], "updated_at": "2026-11-20T10:00:00+00:00"}))
        (folder / "generation.json").write_text(json.dumps({"datasets": [
            {"name": "demo", "role": "sim", "scenes_ok": 23, "scenes_failed": 1,
             "scenes_skipped": 0, "frames": 96, "points_per_frame_mean": 312.4,
             "labels_per_frame_mean": 1.25}]}))
        gap = folder / "gap"
        gap.mkdir(exist_ok=True)
        (gap / "overlay.png").write_bytes(png_bytes())
        (gap / "azimuth.png").write_bytes(png_bytes(32, 32))
        (gap / "gap.json").write_text(json.dumps({
            "sim": {"root": "/data/sim", "frames": 24, "points_per_frame_mean": 300.5,
                    "points_per_frame_median": 290.0},
            "real": {"root": "/data/real", "frames": 24, "points_per_frame_mean": 1200.0,
                     "points_per_frame_median": 1150.0},
            "points_ratio": 0.2504,
            "azimuth": {"edges_deg": [-60, 0, 60], "sim_fraction": [0.5, 0.5],
                        "real_fraction": [0.4, 0.6],
                        "effective_fov_deg": {"sim": 80.5, "real": 110.0}},
            "range": {"edges_m": [0, 5, 10], "sim_fraction": [0.7, 0.3],
                      "real_fraction": [0.6, 0.4]},
            "intensity": {"edges_db": [0, 10], "sim_before": [1.0], "sim_after": [1.0],
                          "real": [1.0], "fitted_on": "train split: 24 frames"},
            "chamfer": {"pairs": 24, "mean_m": 0.231, "per_frame": {}},
            "overlay_frame": "world_000001_f000",
            "figures": {"overlay": "overlay.png", "azimuth": "azimuth.png",
                        "range": "range.png", "escape": "../sweep.json"}}))
    return folder


@pytest.fixture
def sweep_dir(tmp_path):
    return make_sweep(tmp_path / "t")


def _traces(fig: dict, role: str) -> list[dict]:
    return [t for t in fig["data"] if (t.get("meta") or {}).get("role") == role]


# ------------------------------------------------------------------------------ the data
def test_ap_plot_has_one_mean_trace_per_condition_at_the_cell_means(sweep_dir):
    data = dashboard_data(load_sweep(sweep_dir))
    assert [c["name"] for c in data["conditions"]] == ["baseline", "sim-pretrain"]
    ap = data["figures"]["ap"]
    means = _traces(ap, "mean")
    assert [t["meta"]["condition"] for t in means] == ["baseline", "sim-pretrain"]
    assert len(_traces(ap, "trials")) == 2 and len(ap["data"]) == 4   # the count rule
    base, sim = means
    # baseline: 20 + 40 f + trial over trials 0..2 -> mean 21 + 40 f, std 1
    np.testing.assert_allclose(base["y"], [21 + 40 * f for f in FRACTIONS])
    np.testing.assert_allclose(base["error_y"]["array"], [1.0, 1.0, 1.0])
    # sim-pretrain at 50 %: trial 2 failed -> trials 0, 1: 43 + 0, 44 + 0.5
    sim_vals = {f: [ap_of("sim-pretrain", f, t) for t in range(TRIALS)
                    if not (f == 0.5 and t == 2)] for f in FRACTIONS}
    np.testing.assert_allclose(sim["y"], [np.mean(sim_vals[f]) for f in FRACTIONS])
    np.testing.assert_allclose(sim["error_y"]["array"],
                               [np.std(sim_vals[f], ddof=1) for f in FRACTIONS])
    # x: the fraction in %, nudged apart per condition by a few per cent on the log axis
    np.testing.assert_allclose(np.array(base["x"]) / [100 * f for f in FRACTIONS], 1, atol=0.05)
    assert ap["layout"]["xaxis"]["type"] == "log"


def test_trial_points_are_every_finished_run(sweep_dir):
    data = dashboard_data(load_sweep(sweep_dir))
    base_pts, sim_pts = _traces(data["figures"]["ap"], "trials")
    assert len(base_pts["y"]) == 9 and len(sim_pts["y"]) == 8       # one failed run left out
    assert sorted(sim_pts["y"]) == sorted(ap_of("sim-pretrain", f, t) for f in FRACTIONS
                                          for t in range(TRIALS) if (f, t) != (0.5, 2))


#: the constructed sweep's paired differences 3 + 0.5 t: (3, 3.5, 4) at 10 % and 100 %,
#: (3, 3.5) at 50 % (sim-pretrain's trial 2 failed there)
DIFFS = {0.1: [3.0, 3.5, 4.0], 0.5: [3.0, 3.5], 1.0: [3.0, 3.5, 4.0]}


def _half_width(d: list[float], level: float) -> float:
    """Half-width of the two-sided ``level`` Student-t interval of mean(d)."""
    return sps.t.ppf(0.5 + level / 2, len(d) - 1) * np.std(d, ddof=1) / np.sqrt(len(d))


def test_delta_is_the_paired_mean_difference_with_its_simultaneous_interval(sweep_dir):
    data = dashboard_data(load_sweep(sweep_dir))
    (delta,) = _traces(data["figures"]["delta"], "delta")
    assert delta["meta"]["condition"] == "sim-pretrain"
    diffs = DIFFS
    np.testing.assert_allclose(delta["y"], [np.mean(diffs[f]) for f in FRACTIONS])
    # the bars: the 1 - 0.05 / 3 interval (Bonferroni over the condition's 3 fractions)
    half = [_half_width(d, 1 - 0.05 / 3) for d in diffs.values()]
    np.testing.assert_allclose(delta["error_y"]["array"], half, rtol=1e-6)
    np.testing.assert_allclose(delta["error_y"]["arrayminus"], half, rtol=1e-6)
    (points,) = _traces(data["figures"]["delta"], "delta-trials")
    assert sorted(points["y"]) == sorted(sum(diffs.values(), []))
    # Table 1 rows: one per fraction, k/n counts the pairs
    rows = data["summary"]["rows"]
    kn = data["summary"]["columns"].index("k/n")
    assert [r[kn] for r in rows] == ["3/3", "2/2", "3/3"]


def test_learning_curves_have_a_loss_and_a_val_trace_per_finished_run(sweep_dir):
    curves = dashboard_data(load_sweep(sweep_dir))["figures"]["curves"]
    loss, val = _traces(curves, "loss"), _traces(curves, "val_ap")
    assert len(loss) == len(val) == 17
    r = next(t for t in loss if t["meta"]["run_key"].startswith("baseline-0.1-0-"))
    # x is the optimiser step at each epoch's end (10 steps per epoch here)
    assert r["x"] == [10, 20, 30, 40] and r["y"] == pytest.approx([2.0, 1.0, 2 / 3, 0.5])
    # grouped: per condition and fraction a mean line in a min-max band, one legend entry
    # per condition; every trace names its condition and fraction for the table's filters
    means = _traces(curves, "loss_mean")
    assert len(means) == len({(t["meta"]["condition"], t["meta"]["fraction"]) for t in loss})
    assert sum(bool(t.get("showlegend", True)) for t in curves["data"]) == 2
    cell = [t for t in loss if t["meta"]["condition"] == "baseline"
            and t["meta"]["fraction"] == 0.1]
    mean = next(t for t in means if t["meta"]["condition"] == "baseline"
                and t["meta"]["fraction"] == 0.1)
    assert mean["y"][0] == pytest.approx(np.mean([t["y"][0] for t in cell]))
    assert len(_traces(curves, "loss_band")) == 2 * len(means)


def test_runs_table_has_every_run_and_the_metric_first_among_the_aps(sweep_dir):
    runs = dashboard_data(load_sweep(sweep_dir))["runs"]
    keys = [c["key"] for c in runs["columns"]]
    assert len(runs["rows"]) == 18
    first_ap = next(i for i, c in enumerate(runs["columns"]) if c["type"] == "ap")
    assert keys[first_ap] == "ap_3d_r40_iou03"
    status = [r[runs["status_column"]] for r in runs["rows"]]
    assert status.count("failed") == 1 and status.count("ok") == 17
    failed = next(r for r in runs["rows"] if r[runs["status_column"]] == "failed")
    assert failed[keys.index("ap_3d_r40_iou03")] is None
    assert "diverged" in failed[keys.index("error")]


def test_progress_banner_datasets_gap_and_provenance(sweep_dir):
    data = dashboard_data(load_sweep(sweep_dir))
    p = data["progress"]
    assert (p["finished"], p["total"], p["ok"], p["failed"]) == (18, 18, 17, 1)
    assert p["running"] == ["sim-pretrain 100 % t2"] and p["state"] == "complete"
    assert data["banner"]["kind"] == "proxy"
    assert "not claims about measured radar" in data["banner"]["text"]
    assert PROXY in data["banner"]["text"]
    assert {d["role"]: d["domain"] for d in data["datasets"]}["real"] == PROXY
    (gen,) = data["generation"]
    assert (gen["scenes_ok"], gen["scenes_failed"], gen["points_per_frame"]) == (23, 1, "312.4")
    gap = data["gap"]
    assert ["points per frame (mean)", "300.5", "1,200.0"] in gap["rows"]
    assert ["points ratio sim / real", "25.0 %"] in gap["facts"]
    prov = data["provenance"]
    assert prov["versions"]["torch"] == "2.13.0" and "finetune" in prov["configs"]
    assert (prov["settings_digest"], prov["settings_fixed_at"]) == ("0123456789abcdef0123",
                                                                   "2026-11-20T08:00:00+00:00")
    json.dumps(data, allow_nan=False)   # no NaN reaches the page


def test_measured_and_unknown_domains(tmp_path):
    measured = dashboard_data(load_sweep(make_sweep(tmp_path / "m", proxy=False)))
    assert measured["banner"]["kind"] == "measured"
    assert "PROXY" not in measured["banner"]["text"]
    unknown = dashboard_data(load_sweep(make_sweep(tmp_path / "u", sweep_json=False)))
    assert unknown["banner"]["kind"] == "unknown" and unknown["provenance"] is None


def test_undeclared_and_other_declared_domains_are_not_called_measured(tmp_path):
    """The audit's case: a real dataset without a declared domain (and detect-demo-data's
    synthetic frames) showed "Real domain: measured (measured radar)"."""
    und = dashboard_data(load_sweep(make_sweep(tmp_path / "u", proxy=False,
                                               domain="undeclared")))
    assert und["banner"]["kind"] == "undeclared" and "(measured radar)" not in \
        und["banner"]["text"] and "declares no domain" in und["banner"]["text"]
    syn = dashboard_data(load_sweep(make_sweep(tmp_path / "s", proxy=False,
                                               domain="synthetic (detect-demo-data)")))
    assert syn["banner"]["kind"] == "declared"
    assert "synthetic (detect-demo-data)" in syn["banner"]["text"]
    assert "not measured radar" in syn["banner"]["text"]
    # a sweep.json without any domain field: undeclared, not measured
    folder = make_sweep(tmp_path / "n", proxy=False)
    doc = json.loads((folder / "sweep.json").read_text())
    for key in ("real_domain", "real_is_proxy"):
        doc.pop(key)
    doc["datasets"]["real"].pop("domain")
    (folder / "sweep.json").write_text(json.dumps(doc))
    assert dashboard_data(load_sweep(folder))["banner"]["kind"] == "undeclared"
    assert 'id="banner" class="undeclared"' in render_html(dashboard_data(load_sweep(folder)))


def test_summary_has_the_mde_and_p_improved_per_cell_and_says_what_was_detectable(sweep_dir):
    data = dashboard_data(load_sweep(sweep_dir))
    stats = load_sweep(sweep_dir).stats
    cols, rows = data["summary"]["columns"], data["summary"]["rows"]
    i_delta, i_mde = cols.index("Δ"), cols.index("MDE")
    i_kn, i_share = cols.index("k/n"), cols.index("P(improved)")
    # Δ, its unadjusted interval, the simultaneous one the Holm verdict agrees with, the MDE
    i_ci, i_sim = cols.index("95 % CI (unadjusted)"), cols.index(
        "simultaneous 95 % CI (Holm family)")
    assert (i_ci, i_sim, i_mde) == (i_delta + 1, i_delta + 2, i_delta + 3)
    assert i_share == i_kn + 1                                          # beside k/n
    assert "95 % CI" not in cols and "simultaneous CI" not in cols
    assert cols.index("verdict") > i_mde
    note = data["summary"]["interval_note"]
    assert "Holm-adjusted" in note and "simultaneous 95 % CI" in note
    assert "may exclude 0 beside \"no detectable difference\"" in note
    for row, comp in zip(rows, stats["comparisons"], strict=True):
        assert row[i_mde] == f"{comp['mde']:.1f}" and row[i_delta].startswith("+")
        assert row[i_share].startswith(f"{100 * comp['p_improved']:.0f} % [")
    # with 2 or 3 pairs of spread 0.5 the MDE at alpha / 3 is several AP points
    assert all(c["mde"] > 2.0 and c["mde_alpha"] == pytest.approx(0.05 / 3)
               for c in stats["comparisons"])
    assert data["summary"]["numeric"][cols.index("verdict")] is False
    assert data["summary"]["numeric"][i_mde] is True
    (sentence,) = data["summary"]["sentences"]
    assert data["summary"]["sentences"] == detectability_sentences(stats)
    assert sentence.startswith("Sim Pretrain vs Baseline: with 2 to 3 trials per fraction this "
                               "sweep could detect gains of ≥ ")
    # the paper's +0.9 (10 %) and +1.2 (50 %) are below this sweep's MDE there, +3.7 is not
    assert "below it at 10 %, 50 % and at or above it at 100 %" in sentence
    page = render_html(data)
    assert _embedded(page)["summary"]["sentences"] == [sentence]


def test_delta_plot_shows_the_mde_and_the_papers_delta(sweep_dir):
    data = dashboard_data(load_sweep(sweep_dir))
    stats = load_sweep(sweep_dir).stats
    (mde,) = _traces(data["figures"]["delta"], "mde")
    assert mde["meta"]["condition"] == "sim-pretrain"
    np.testing.assert_allclose(mde["y"], [c["mde"] for c in stats["comparisons"]])
    np.testing.assert_allclose(mde["x"], [100 * f for f in FRACTIONS])
    (paper,) = _traces(data["figures"]["delta"], "paper-delta")
    assert paper["y"] == [0.9, 1.2, 3.7] and paper["x"] == [10.0, 50.0, 100.0]
    (delta,) = _traces(data["figures"]["delta"], "delta")
    assert [c[6] for c in delta["customdata"]] == [f"{c['mde']:.2f}"
                                                   for c in stats["comparisons"]]
    assert delta["customdata"][0][7] == "100 % [29, 100]"           # P(improved), 3/3


def test_delta_bars_are_the_simultaneous_interval_and_an_old_stats_json_the_unadjusted(
        sweep_dir):
    stats = load_sweep(sweep_dir).stats
    (delta,) = _traces(dashboard_data(load_sweep(sweep_dir))["figures"]["delta"], "delta")
    for i, comp in enumerate(stats["comparisons"]):
        lo, hi = comp["t_ci_simultaneous"]
        assert delta["error_y"]["array"][i] == pytest.approx(hi - comp["mean_diff"])
        assert delta["error_y"]["arrayminus"][i] == pytest.approx(comp["mean_diff"] - lo)
        # wider than the unadjusted interval, which the hover gives beside it
        assert hi > comp["t_ci"][1] and lo < comp["t_ci"][0]
        assert delta["customdata"][i][8] == "[{:+.2f}, {:+.2f}]".format(*comp["t_ci"])
    fig = dashboard_data(load_sweep(sweep_dir))["figures"]["delta"]
    assert "simultaneous 95 % CI, Holm family" in fig["layout"]["yaxis"]["title"]["text"]
    assert "simultaneous 95 % CI, Holm family" in delta["hovertemplate"]
    # a stats.json written before the simultaneous interval: the unadjusted one, said so
    old = dict(stats, comparisons=[{k: v for k, v in c.items() if k != "t_ci_simultaneous"}
                                   for c in stats["comparisons"]])
    (sweep_dir / "stats.json").write_text(json.dumps(old))
    data = dashboard_data(load_sweep(sweep_dir))
    (delta,) = _traces(data["figures"]["delta"], "delta")
    np.testing.assert_allclose(delta["error_y"]["array"],
                               [_half_width(d, 0.95) for d in DIFFS.values()], rtol=1e-6)
    assert "95 % t-interval, unadjusted" in data["figures"]["delta"]["layout"]["yaxis"][
        "title"]["text"]
    sim = data["summary"]["columns"].index("simultaneous 95 % CI (Holm family)")
    assert {r[sim] for r in data["summary"]["rows"]} == {"—"}
    assert "written before the simultaneous interval" in data["summary"]["interval_note"]


def _primary_sweep(folder: Path) -> Path:
    """The constructed sweep with a diagnostic condition listed before the primary one and
    the primary endpoint pooled over 10 % and 50 %."""
    make_sweep(folder, conditions=("baseline", "sim-gt-pretrain", "sim-pretrain"))
    edit_sweep_json(folder, primary_fractions=[0.1, 0.5], primary_condition="sim-pretrain")
    return folder


def test_primary_endpoint_rows_and_sentence_put_the_primary_first(tmp_path):
    sweep = load_sweep(_primary_sweep(tmp_path / "p"))
    assert [c["condition"] for c in sweep.stats["pooled"]] == ["sim-gt-pretrain",
                                                               "sim-pretrain"]
    primary = dashboard_data(sweep)["primary"]
    cols = primary["columns"]
    assert cols[:3] == ["condition", "role", "trials"] and cols[-1] == "verdict"
    first, second = primary["rows"]
    assert first[:2] == ["Sim Pretrain", "primary"]
    assert second[:2] == ["Sim-GT Pretrain", "diagnostic"]
    # sim-pretrain's trial 2 failed at 50 %: trials 0 and 1 are complete at 10 % and 50 %;
    # per trial the mean of its differences there is 3 + 0.5 t, so Δ = 3.25 from (3, 3.5)
    assert first[2] == 2 and second[2] == 3
    d = [3.0, 3.5]
    lo, hi = np.mean(d) - _half_width(d, 0.95), np.mean(d) + _half_width(d, 0.95)
    assert first[cols.index("Δ [95 % CI]")] == f"+3.2 [{lo:+.1f}, {hi:+.1f}]"
    # baseline at 10 % and 50 %: 20 + 40 f + t over trials 0, 1 -> 20 + 12 + 0.5 = 32.5
    assert first[cols.index("Baseline")] == "32.5"
    assert first[cols.index("condition AP")] == "35.8"            # 32.5 + 3.25
    assert first[cols.index("k/n")] == "2/2"
    p = sps.ttest_rel([35.0, 36.5], [32.0, 33.0]).pvalue
    assert first[cols.index("p")] == f"{p:.3f}"
    assert first[-1] == ("gain" if p < 0.05 else "no detectable difference")
    pooled = next(c for c in sweep.stats["pooled"] if c["primary"])
    assert first[cols.index("MDE")] == f"{pooled['mde']:.1f}"
    assert primary["numeric"][cols.index("trials")] and not primary["numeric"][-1]
    assert primary["sentence"] == (
        "Primary endpoint (pre-registered): Sim Pretrain vs Baseline pooled over 10 %, 50 %: "
        f"Δ +3.2 AP [{lo:+.1f}, {hi:+.1f}] (95 % CI, 2 trials), MDE {pooled['mde']:.1f} AP at "
        f"80 % power, {first[-1]}.")
    assert "no family adjustment" in primary["note"]


def test_an_old_stats_json_without_the_pooled_endpoint_renders_without_it(tmp_path):
    folder = _primary_sweep(tmp_path / "o")
    old = {k: v for k, v in load_sweep(folder).stats.items()
           if k not in ("pooled", "primary", "pretrainings")}
    (folder / "stats.json").write_text(json.dumps(old))
    sweep = load_sweep(folder)
    assert sweep.stats_source == "stats.json" and "pooled" not in sweep.stats
    data = dashboard_data(sweep)
    assert data["primary"] == {"sentence": None, "note": None, "columns": [], "rows": [],
                               "numeric": []}
    assert data["pretrainings"]["n"] == 0 and data["pretrainings"]["figures"] == {
        "check": None, "loss": None}
    page = render_html(data)
    assert 'id="primary-section"' in page and "No pre-training recorded." in page
    assert _embedded(page) == data


def _pretrain_sweep(folder: Path, thresholds: dict | None = None) -> Path:
    """The constructed sweep with three sim pre-trainings: trials 0 and 1 checked (held-out
    30 / 40, zero-shot 5 / 7, train 60 / 70), trial 2 failed after one epoch."""
    make_sweep(folder)
    if thresholds is not None:
        edit_sweep_json(folder, learnability_thresholds=thresholds)
    write_pretrainings(folder, [
        pretrain_row(0, heldout=30.0, zero_shot=5.0, train=60.0, loss=(3.0, 2.0, 1.5)),
        pretrain_row(1, heldout=40.0, zero_shot=7.0, train=70.0, loss=(2.8, 1.9, 1.2)),
        pretrain_row(2, status="failed", loss=(3.3,),
                     error="RuntimeError: diverged </script><b>pre</b>"),
    ])
    return folder


def test_pretrainings_are_read_summarised_and_plotted(tmp_path):
    folder = _pretrain_sweep(tmp_path / "t", thresholds={"sim-pretrain": 35.0})
    sweep = load_sweep(folder)
    assert [r["pretrain_id"] for r in sweep.pretrainings] == [
        "pretrain-sim-t0", "pretrain-sim-t1", "pretrain-sim-t2"]
    pre = dashboard_data(sweep)["pretrainings"]
    assert (pre["n"], pre["n_failed"]) == (3, 1)
    (summary,) = pre["summary"]["rows"]
    sd = np.std([30.0, 40.0], ddof=1)                                      # 7.07
    assert summary == ["Sim Pretrain", "sim", 2, 1, f"65.0 ± {sd:.1f}", f"35.0 ± {sd:.1f}",
                       f"6.0 ± {np.std([5.0, 7.0], ddof=1):.1f}", "35.0 (met 1/2)"]
    cols = pre["table"]["columns"]
    rows = {r[0]: r for r in pre["table"]["rows"]}
    assert rows["pretrain-sim-t1"][cols.index("held-out sim AP")] == "40.0"
    assert rows["pretrain-sim-t1"][cols.index("threshold")] == "Sim Pretrain: met"
    assert rows["pretrain-sim-t0"][cols.index("threshold")] == "Sim Pretrain: not met"
    failed = rows["pretrain-sim-t2"]
    assert failed[cols.index("status")] == "failed" and "diverged" in failed[cols.index("error")]
    assert failed[cols.index("held-out sim AP")] == "—"
    # loss curves: one per pre-training that did not fail, its loss per epoch
    loss = _traces(pre["figures"]["loss"], "pretrain_loss")
    assert [t["meta"]["pretrain_id"] for t in loss] == ["pretrain-sim-t0", "pretrain-sim-t1"]
    assert loss[0]["y"] == [3.0, 2.0, 1.5] and loss[1]["y"] == [2.8, 1.9, 1.2]
    assert loss[0]["x"] == [1, 2, 3]
    assert {t["line"]["color"] for t in loss} == {"#d62728"}               # sim-pretrain's
    assert {t["legendgroup"] for t in loss} == {"sim"}
    assert [t["showlegend"] for t in loss] == [True, False]                # one per role
    # checks: held-out and zero-shot APs of the two checked ones, and the threshold line
    check = _traces(pre["figures"]["check"], "pretrain_check")
    by = {t["meta"]["measure"]: t for t in check}
    assert sorted(by["heldout"]["y"]) == [30.0, 40.0]
    assert sorted(by["zero_shot"]["y"]) == [5.0, 7.0]
    assert by["threshold"]["y"] == [35.0, 35.0] and by["threshold"]["line"]["dash"] == "dash"
    assert pre["figures"]["check"]["layout"]["xaxis"]["ticktext"] == ["Sim Pretrain"]
    # the statistics carry the same table (sweep_statistics on the live sweep)
    assert sweep.stats["pretrainings"]["thresholds"] == {"sim-pretrain": 35.0}
    data = dashboard_data(sweep)
    json.dumps(data, allow_nan=False)
    page = render_html(data)
    assert _embedded(page) == data
    assert "</script><b>pre</b>" not in page                     # the error cannot close it
    for needle in ('id="pretrain-section"', "<h2>Pre-trainings</h2>", 'id="plot-pretrain-check"',
                   'id="plot-pretrain-loss"', 'id="pretrain-rows"', "<h2>Primary endpoint</h2>",
                   'id="summary-note"'):
        assert needle in page, needle


def test_pretrainings_without_a_threshold_draw_no_threshold_line(tmp_path):
    pre = dashboard_data(load_sweep(_pretrain_sweep(tmp_path / "t")))["pretrainings"]
    assert pre["summary"]["rows"][0][-1] == "—"
    measures = [t["meta"]["measure"] for t in _traces(pre["figures"]["check"],
                                                      "pretrain_check")]
    assert measures == ["heldout", "zero_shot"]


def test_a_stats_json_without_the_pretraining_table_gets_it_from_the_parquet(tmp_path):
    folder = _pretrain_sweep(tmp_path / "t", thresholds={"sim-pretrain": 35.0})
    stats = load_sweep(folder).stats
    (folder / "stats.json").write_text(json.dumps(
        {k: v for k, v in stats.items() if k != "pretrainings"}))
    sweep = load_sweep(folder)
    assert sweep.stats_source.startswith("stats.json (pre-training table from "
                                         "pretrainings.parquet")
    assert sweep.stats["pretrainings"] == stats["pretrainings"]
    # a fourth pre-training finished after stats.json was written: the table follows the file
    (folder / "stats.json").write_text(json.dumps(stats))
    assert load_sweep(folder).stats_source == "stats.json"
    rows = pq.read_table(folder / "pretrainings.parquet").to_pylist()
    write_pretrainings(folder, [*rows, pretrain_row(3, heldout=50.0)])
    table = load_sweep(folder).stats["pretrainings"]
    assert len(table["rows"]) == 4 and table["summary"][0]["n_met"] == 2


def test_every_run_and_trial_point_names_its_run_folder(sweep_dir):
    data = dashboard_data(load_sweep(sweep_dir))
    runs = data["runs"]
    keys = [c["key"] for c in runs["columns"]]
    folder = keys.index("run_folder")
    for row in runs["rows"]:
        if row[runs["status_column"]] == "failed":
            continue
        cond, f, t = row[keys.index("condition")], row[keys.index("fraction")], row[
            keys.index("trial")]
        assert row[folder] == f"runs/{cond}-{f:g}-{t}"      # checkpoint t/runs/.../last.pt
        # the sweep folder joined with it holds the run's checkpoint
        assert (sweep_dir / row[folder] / "last.pt").relative_to(sweep_dir.parent).as_posix() \
            == row[keys.index("checkpoint")]
    failed = next(r for r in runs["rows"] if r[runs["status_column"]] == "failed")
    assert failed[folder] == "runs/" + failed[keys.index("run_key")]   # no checkpoint
    # condition names (shown by label), and the group and metric columns the page uses
    assert {r[keys.index("condition")] for r in runs["rows"]} == {"baseline", "sim-pretrain"}
    assert [keys[i] for i in runs["group_columns"]] == ["condition", "fraction", "trial"]
    assert keys[runs["metric_column"]] == "ap_3d_r40_iou03"
    # the AP plot's trial points name the folder of the run behind each value
    base_pts, _ = _traces(data["figures"]["ap"], "trials")
    assert base_pts["customdata"][0] == ["10 %", 0, "runs/baseline-0.1-0"]
    assert "run folder" in base_pts["hovertemplate"]


def test_run_folder_is_relative_to_the_sweep():
    assert run_folder({"checkpoint": "s/runs/k1/last.pt", "run_key": "k1"}, "s") == "runs/k1"
    # found finished in the store: trained by another sweep
    assert run_folder({"checkpoint": "old/runs/k2/last.pt", "run_key": "k2"}, "s") == \
        "../old/runs/k2"
    assert run_folder({"checkpoint": "", "run_key": "k3"}, "s") == "runs/k3"    # failed
    assert run_folder({"checkpoint": "/abs/x/runs/k4/last.pt"}, "s") == "/abs/x/runs/k4"
    assert run_folder({}, "s") is None


def test_stats_json_is_used_while_it_counts_the_runs_and_recomputed_when_stale(sweep_dir):
    fresh = load_sweep(sweep_dir)
    assert fresh.stats_source.startswith("computed")             # none written yet
    marked = dict(fresh.stats, notes=["from stats.json"])
    (sweep_dir / "stats.json").write_text(json.dumps(marked))
    assert load_sweep(sweep_dir).stats["notes"] == ["from stats.json"]
    append_run(sweep_dir, run_row("baseline", 0.25, 0))            # the sweep went on
    again = load_sweep(sweep_dir)
    assert again.stats["notes"] != ["from stats.json"] and "0.25" not in again.stats_source
    assert 0.25 in again.stats["fractions"]


# ------------------------------------------------------------------------------ the page
def _embedded(page: str) -> dict:
    m = re.search(r'<script type="application/json" id="dashboard-data">(.*?)</script>', page,
                  re.S)
    return json.loads(m.group(1))


def test_the_page_is_self_contained(sweep_dir, tmp_path):
    from plotly.offline import get_plotlyjs

    out = write_dashboard(sweep_dir, tmp_path / "page" / "d.html")
    page = out.read_text(encoding="utf-8")
    assert get_plotlyjs()[:2000] in page and get_plotlyjs()[-2000:] in page   # bundle inline
    tags = re.findall(r"<(?:script|link|img|iframe)\b[^>]*>", page, re.I)
    assert tags and not [t for t in tags
                         if re.search(r"\b(src|href)\s*=\s*[\"']?\s*(https?:)?//", t, re.I)]
    assert not re.search(r"<script[^>]*\bsrc\s*=", page, re.I)         # every script inline
    assert not re.search(r"<link\b", page, re.I)                        # no stylesheet links
    csp = re.search(r'http-equiv="Content-Security-Policy" content="([^"]+)"', page).group(1)
    assert "default-src &#x27;none&#x27;" in csp and "connect-src &#x27;none&#x27;" in csp
    assert _embedded(page) == dashboard_data(load_sweep(sweep_dir))
    assert "PROXY real domain" in page                                # banner without JS
    assert '"poll_ms":0' in page                                      # static: no polling


def test_text_in_the_data_cannot_close_the_script(sweep_dir):
    data = dashboard_data(load_sweep(sweep_dir))
    page = render_html(data)
    assert "</script><b>x</b>" not in page
    keys = [c["key"] for c in data["runs"]["columns"]]
    errors = [r[keys.index("error")] for r in _embedded(page)["runs"]["rows"]]
    assert "RuntimeError: diverged </script><b>x</b>" in errors


@pytest.mark.parametrize("case", ["empty", "baseline only", "all failed", "no extras",
                                  "sweep started"])
def test_partial_sweeps_render(tmp_path, case):
    folder = tmp_path / "p"
    if case == "empty":
        make_sweep(folder, ran=())
    elif case == "baseline only":
        make_sweep(folder, ran=("baseline",), failed=())
    elif case == "all failed":
        make_sweep(folder, failed={(c, f, t) for c in ("baseline", "sim-pretrain")
                                   for f in FRACTIONS for t in range(TRIALS)})
    elif case == "no extras":
        make_sweep(folder, extras=False, sweep_json=False)
    else:
        make_sweep(folder)
        (folder / "runs.parquet").unlink()
    sweep = load_sweep(folder, require_runs=case != "sweep started")
    data = dashboard_data(sweep)
    json.dumps(data, allow_nan=False)
    page = render_html(data)
    assert _embedded(page) == data
    assert [c["name"] for c in data["conditions"]] == ["baseline", "sim-pretrain"]
    assert len(_traces(data["figures"]["ap"], "mean")) == 2      # the count rule, always
    finished = {"empty": 0, "baseline only": 9, "all failed": 18, "no extras": 18,
                "sweep started": 0}[case]
    assert data["progress"]["finished"] == len(data["runs"]["rows"]) == finished
    if case in ("empty", "sweep started"):
        assert data["progress"]["state"] == "not started" and data["progress"]["total"] == 18
        assert all(not t["y"] for t in data["figures"]["ap"]["data"])
    if case == "baseline only":   # sim-pretrain is planned: listed, with nothing to plot yet
        assert _traces(data["figures"]["ap"], "mean")[1]["y"] == []
        assert _traces(data["figures"]["delta"], "delta")[0]["y"] == []
    if case == "all failed":
        assert data["progress"]["failed"] == 18
        assert all(c["verdict"] == "insufficient trials"
                   for c in sweep.stats["comparisons"])


@pytest.mark.parametrize("case,named", [
    ("missing folder", "nowhere"),
    ("no runs.parquet", "runs.parquet"),
    ("damaged runs.parquet", "runs.parquet"),
    ("malformed sweep.json", "sweep.json"),
    ("malformed stats.json", "stats.json"),
    ("stats.json without cells", "stats.json"),
    ("gap.json not an object", "gap.json"),
    ("damaged pretrainings.parquet", "pretrainings.parquet"),
    ("pretrainings.parquet of another table", "pretrainings.parquet"),
    ("thresholds not numbers", "sweep.json"),
])
def test_bad_sweep_folders_name_the_file_and_the_fix(tmp_path, case, named):
    folder = make_sweep(tmp_path / "b")
    if case == "missing folder":
        folder = tmp_path / "nowhere"
    elif case == "no runs.parquet":
        (folder / "runs.parquet").unlink()
    elif case == "damaged runs.parquet":
        (folder / "runs.parquet").write_bytes(b"PAR1 not really")
    elif case == "malformed sweep.json":
        (folder / "sweep.json").write_text('{"name": "b",')
    elif case == "malformed stats.json":
        (folder / "stats.json").write_text("{nan}")
    elif case == "stats.json without cells":
        (folder / "stats.json").write_text('{"conditions": []}')
    elif case == "damaged pretrainings.parquet":
        (folder / "pretrainings.parquet").write_bytes(b"PAR1 not really")
    elif case == "pretrainings.parquet of another table":
        pq.write_table(pq.read_table(folder / "runs.parquet"), folder / "pretrainings.parquet")
    elif case == "thresholds not numbers":
        edit_sweep_json(folder, learnability_thresholds={"sim-pretrain": "high"})
    else:
        (folder / "gap" / "gap.json").write_text("[1, 2]")
    with pytest.raises(SweepFolderError) as info:
        load_sweep(folder)
    msg = str(info.value)
    assert named in msg and "\n" not in msg
    assert re.search(r"rerun|delete|give|run `sim2radar", msg), msg


# ------------------------------------------------------------------------------ the CLI
def _cli(*args):
    from typer.testing import CliRunner

    from sim2radar.cli import app

    return CliRunner().invoke(app, ["dashboard", *map(str, args)])


def test_cli_writes_the_page_and_prints_its_path(sweep_dir, tmp_path):
    out = tmp_path / "dash.html"
    res = _cli(sweep_dir, "--out", out)
    assert res.exit_code == 0, res.output
    assert res.output.strip() == str(out) and out.stat().st_size > 1_000_000
    # by name under --root
    res = _cli("t", "--root", sweep_dir.parent, "--out", tmp_path / "by_name.html")
    assert res.exit_code == 0, res.output
    assert _embedded((tmp_path / "by_name.html").read_text())["name"] == "t"


@pytest.mark.parametrize("case", ["missing", "no runs", "malformed json", "no action"])
def test_cli_bad_input_is_one_line_and_exit_2(sweep_dir, tmp_path, case):
    args = [sweep_dir, "--out", tmp_path / "x.html"]
    if case == "missing":
        args[0] = tmp_path / "nope"
    elif case == "no runs":
        (sweep_dir / "runs.parquet").unlink()
    elif case == "malformed json":
        (sweep_dir / "progress.json").write_text("{")
    else:
        args = [sweep_dir]
    res = _cli(*args)
    assert res.exit_code == 2
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), res.output
    assert "Traceback" not in res.output
    expected = {"missing": "nope", "no runs": "runs.parquet", "malformed json": "progress.json",
                "no action": "--out"}[case]
    assert expected in lines[0]
    assert not (tmp_path / "x.html").exists()


def test_cli_serve_prints_the_url_serves_and_stops_on_ctrl_c(sweep_dir):
    exe = Path(sys.executable).with_name("sim2radar")
    # Ctrl-C in a terminal: the child starts with SIGINT's default action. A suite run as a
    # background job (`make test &`, nohup, some CI shells) has SIGINT ignored, the child
    # inherits that, and Python then installs no KeyboardInterrupt handler: SIGINT did nothing
    # and the test waited (the fresh-clone failures; the stack dump below showed the CLI still
    # in its sleep loop). faulthandler: if it does not stop, SIGABRT prints every thread's stack.
    proc = subprocess.Popen([str(exe), "dashboard", str(sweep_dir), "--serve", "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONFAULTHANDLER": "1"},
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 60)
        assert ready, "no URL printed within 60 s"
        line = proc.stdout.readline()
        url = re.search(r"http://127\.0\.0\.1:\d+/", line).group(0)
        with urllib.request.urlopen(url + "data.json", timeout=10) as r:
            assert json.load(r)["progress"]["finished"] == 18
        # issue #24: a page of another site resolving its name to 127.0.0.1 is refused
        port = int(url.rsplit(":", 1)[1].strip("/"))
        status, body = _get_with_host(port, "/data.json", f"rebind.example:{port}")
        assert status == 403 and body.startswith(b"forbidden: Host 'rebind.example:")
        proc.send_signal(signal.SIGINT)
        # communicate drains both pipes (a child blocked on a full stderr pipe never exits);
        # 30 s: a fresh clone's suite on 2 shared cores once took over 10 s to reap it
        try:
            out, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGABRT)
            out, err = proc.communicate(timeout=30)
            pytest.fail(f"no exit 30 s after SIGINT; its threads at SIGABRT:\n{err}")
        assert proc.returncode == 0, err
        assert "stopped" in out, (out, err)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


# ------------------------------------------------------------------------------ the server
def _get(url: str) -> tuple[int, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def test_server_serves_the_live_page_and_fresh_data(sweep_dir):
    with serve_dashboard(sweep_dir, poll_s=0.5) as server:
        assert server.host == "127.0.0.1" and server.port > 0
        status, page = _get(server.url)
        assert status == 200 and b'"poll_ms":500' in page
        assert b"connect-src &#x27;self&#x27;" in page
        status, body = _get(server.url + "data.json")
        assert status == 200 and json.loads(body)["progress"]["finished"] == 18
        append_run(sweep_dir, run_row("baseline", 0.25, 0))
        time.sleep(0.05)  # a new mtime/size signature
        data = json.loads(_get(server.url + "data.json")[1])
        assert data["progress"]["finished"] == 19 and len(data["runs"]["rows"]) == 19
        # a broken file mid-sweep: 503 with the reason; the page still loads (last good data)
        (sweep_dir / "progress.json").write_text("{")
        status, body = _get(server.url + "data.json")
        assert status == 503 and "progress.json" in json.loads(body)["error"]
        status, page = _get(server.url)
        assert status == 200 and '"finished":19' in page.decode()
        assert _get(server.url + "etc/passwd")[0] == 404
        url = server.url
    with pytest.raises(urllib.error.URLError):
        urllib.request.urlopen(url + "data.json", timeout=2)


def _get_with_host(port: int, path: str, host: str | None) -> tuple[int, bytes]:
    """GET ``path`` from 127.0.0.1:``port`` with this ``Host`` header (None: none sent)."""
    import http.client

    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        conn.putrequest("GET", path, skip_host=True)
        if host is not None:
            conn.putheader("Host", host)
        conn.endheaders()
        r = conn.getresponse()
        return r.status, r.read()
    finally:
        conn.close()


@pytest.mark.parametrize("host, allowed", [
    ("127.0.0.1:{port}", True), ("127.0.0.1", True), ("localhost:{port}", True),
    ("LocalHost", True), ("[::1]:{port}", True), ("[::1]", True),
    ("localhost:9000", True),  # a port forward (ssh -L 9000:127.0.0.1:PORT) keeps working
    ("rebind.example:{port}", False), ("rebind.example", False),
    ("127.0.0.1.rebind.example:{port}", False), ("localhost.evil:{port}", False),
    ("127.0.0.1:{port}@evil", False), ("[::1]evil", False), ("", False), (None, False),
])
def test_server_answers_only_requests_for_a_loopback_host(sweep_dir, host, allowed):
    """Issue #24 (DNS rebinding): a page on rebind.example whose name resolves to 127.0.0.1
    reaches the port, but its requests carry ``Host: rebind.example``; they get 403 and a
    one-line body naming the URL to open; loopback names (any port) are served."""
    with serve_dashboard(sweep_dir) as server:
        h = None if host is None else host.format(port=server.port)
        for path in ("/", "/data.json", "/nothing-here"):
            status, body = _get_with_host(server.port, path, h)
            if allowed:
                assert status in (200, 404), (h, path, status)
            else:
                assert status == 403, (h, path, status)
                text = body.decode()
                assert text == (f"forbidden: Host {h!r} is not this loopback server; open "
                                f"http://127.0.0.1:{server.port}/\n")
                assert b"<html" not in body and b"finished" not in body


def test_server_binds_loopback_only_and_checks_the_folder_first(sweep_dir, tmp_path):
    with pytest.raises(ValueError, match="loopback"):
        serve_dashboard(sweep_dir, host="0.0.0.0")
    with pytest.raises(SweepFolderError, match="no such sweep folder"):
        serve_dashboard(tmp_path / "missing")


def test_the_columns_the_page_reads_are_the_run_tables_columns():
    """The dashboard checks runs.parquet against RUNS_COLUMNS without importing the store (the
    library sits below it): every column it reads must exist in experiment_runs with a type
    of that kind, and the identity columns must be the schema's non-nullable ones."""
    from sim2radar.experiment.dashboard.reading import _RUN_IDENTITY, RUNS_COLUMNS, _holds

    schema = get_schema("experiment_runs").schema
    for name, kind in RUNS_COLUMNS.items():
        assert name in schema.names, name
        assert _holds(schema.field(name).type, kind), (name, kind, schema.field(name).type)
    for name in _RUN_IDENTITY:
        assert not schema.field(name).nullable, name


def test_many_tabs_at_once_closed_tabs_and_ctrl_c_mid_request(sweep_dir, capsys):
    """Issue #33, probe 7: 200 concurrent page loads are all answered and the page is rendered
    once (not per request); a client that hangs up mid-answer prints nothing; stopping while a
    request is still being answered returns at once."""
    import socket
    import threading
    from concurrent.futures import ThreadPoolExecutor

    with serve_dashboard(sweep_dir, poll_s=0.5) as server:
        t0 = time.perf_counter()
        with ThreadPoolExecutor(200) as pool:
            statuses = list(pool.map(lambda _: _get(server.url)[0], range(200)))
        assert statuses == [200] * 200, statuses.count(200)
        assert server.renders == 1
        assert time.perf_counter() - t0 < 90
        for _ in range(20):  # ask for the page, then hang up before reading it
            with socket.create_connection((server.host, server.port)) as s:
                s.sendall(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
                s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\0\0\0\0\0\0\0")
        time.sleep(0.5)
        slow = threading.Event()
        real = server.page_bytes

        def slow_page() -> bytes:
            slow.set()
            time.sleep(5.0)
            return real()

        server.page_bytes = slow_page
        threading.Thread(target=lambda: _get(server.url), daemon=True).start()
        assert slow.wait(5.0)
        t0 = time.perf_counter()
        server.stop()
        assert time.perf_counter() - t0 < 2.0
    err = capsys.readouterr().err
    assert "Traceback" not in err and "BrokenPipe" not in err and "ConnectionReset" not in err


def test_pre_trainings_finishing_before_any_run_show_in_the_progress(tmp_path):
    """Issue #34, item 5: at minute 7 the live page said "0 of 30 (not started)" while 10 of 15
    pre-trainings had finished; now progress counts them and says "pre-training"."""
    folder = tmp_path / "s"
    make_sweep(folder, ran=(), extras=False)
    write_pretrainings(folder, [pretrain_row(0, heldout=30.0, zero_shot=5.0, train=60.0,
                                             loss=(3.0, 2.0))])
    (folder / "progress.json").write_text(json.dumps({
        "total_runs": 12, "finished": 0, "failed": 0, "total_pretrainings": 3,
        "pretrainings_finished": 1, "updated_at": "2026-11-20T10:00:00+00:00"}))
    p = dashboard_data(load_sweep(folder, require_runs=False))["progress"]
    assert (p["state"], p["finished"]) == ("pre-training", 0)
    assert (p["pretrainings_finished"], p["pretrainings_total"]) == (1, 3)
    page = render_html(dashboard_data(load_sweep(folder, require_runs=False)))
    assert '"pretrainings_finished":1' in page and "pre-trainings finished" in page


def test_provenance_names_the_datasets_used_and_the_git_commit(tmp_path):
    """Issue #34, item 5: provenance showed the detector config's placeholder data.root;
    now it shows the sweep's datasets (path, content key, domain) in its place, and the git
    commit the sweep ran from (a checkout: this one)."""
    from sim2radar.storage.provenance import git_commit

    folder = make_sweep(tmp_path / "s")
    doc = json.loads((folder / "sweep.json").read_text())
    doc["provenance"]["configs"]["finetune"]["data"] = {"root": "../../data/ifr"}
    doc["provenance"]["git"] = git_commit()
    (folder / "sweep.json").write_text(json.dumps(doc))
    prov = dashboard_data(load_sweep(folder))["provenance"]
    assert "../../data/ifr" not in prov["configs"]["finetune"]
    assert "/data/real" in prov["configs"]["finetune"]
    assert prov["datasets"]["real"] == {"path": "/data/real", "key": "r" * 16,
                                        "domain": PROXY}
    commit = git_commit()
    assert commit is None or re.fullmatch(r"[0-9a-f]{40}(-dirty)?", commit)
    assert prov["git"] == commit
