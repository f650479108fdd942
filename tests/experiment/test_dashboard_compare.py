"""Two sweeps compared (sim2radar/experiment/dashboard/compare.py, ``sim2radar dashboard A B
--out``): per condition and fraction both ran, each sweep's mean AP with its t-interval and
the difference of their Δs to the baseline with Welch's interval (checked against SciPy's
Welch test); the settings that differ; what only one sweep ran; a sweep on another metric;
the CLI.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy import stats as sps

from sim2radar.experiment.dashboard import compare_data, load_sweep
from sim2radar.experiment.dashboard.compare import welch_interval
from tests.experiment.test_dashboard import _cli, ap_of, make_sweep, write_runs

METRIC = "ap_3d_r40_iou03"


def _shift(trial: int) -> float:
    """Sweep B's sim-pretrain gains 2 + 0.25 trial AP points over A's."""
    return 2.0 + 0.25 * trial


@pytest.fixture
def sweeps(tmp_path):
    """A: the constructed sweep (baseline, sim-pretrain at 10, 50, 100 %; sim-pretrain's
    trial 2 at 50 % failed). B: baseline, sim-pretrain and sim-gt-pretrain at 10, 25, 50 %,
    nothing failed, sim-pretrain ``_shift`` higher, other trial seeds, another sweep seed,
    real dataset and commit."""
    a = make_sweep(tmp_path / "a")
    b = make_sweep(tmp_path / "b", conditions=("baseline", "sim-pretrain", "sim-gt-pretrain"),
                   fractions=(0.1, 0.25, 0.5), failed=())
    rows = pq.read_table(b / "runs.parquet").to_pylist()
    for r in rows:
        r["seed"] = 2000 + r["trial"]
        if r["condition"] == "sim-pretrain":
            r[METRIC] += _shift(r["trial"])
    write_runs(b, rows)
    doc = json.loads((b / "sweep.json").read_text())
    doc["profile"]["sweep_seed"] = 1
    doc["datasets"]["real"].update(path="/data/real2", key="x" * 16)
    doc["provenance"]["git"] = "f" * 40
    (b / "sweep.json").write_text(json.dumps(doc))
    return a, b


def _cell(data: dict, cond: str, fraction: float) -> dict:
    return next(c for c in data["cells"] if c["condition"] == cond and c["fraction"] == fraction)


def _delta(data: dict, cond: str, fraction: float) -> dict:
    return next(c for c in data["deltas"]
                if c["condition"] == cond and c["fraction"] == fraction)


def test_welch_interval_is_scipys_welch_interval():
    rng = np.random.default_rng(4)
    x, y = rng.normal(1.0, 1.0, 5), rng.normal(3.0, 2.5, 8)
    got = welch_interval(x.mean(), x.std(ddof=1), 5, y.mean(), y.std(ddof=1), 8, alpha=0.1)
    ref = sps.ttest_ind(y, x, equal_var=False).confidence_interval(0.9)
    assert got["diff"] == pytest.approx(y.mean() - x.mean())
    np.testing.assert_allclose(got["ci"], [ref.low, ref.high], rtol=1e-9)
    assert got["note"] is None
    one = welch_interval(1.0, None, 1, 2.0, 0.5, 4)
    assert one["diff"] == 1.0 and one["ci"] == [None, None] and "fewer than 2" in one["note"]


def test_shared_cells_have_both_means_with_intervals_and_the_difference_of_deltas(sweeps):
    a, b = sweeps
    data = compare_data(load_sweep(a), load_sweep(b))
    assert data["metric"] == METRIC and data["level"] == "95 %"
    assert [(c["condition"], c["fraction"]) for c in data["cells"]] == [
        ("baseline", 0.1), ("baseline", 0.5), ("sim-pretrain", 0.1), ("sim-pretrain", 0.5)]
    # A's baseline at 10 %: 24, 25, 26 -> mean 25 with the t-interval of 3 trials
    base = _cell(data, "baseline", 0.1)
    half = sps.t.ppf(0.975, 2) * 1.0 / np.sqrt(3)
    assert base["a"]["mean"] == pytest.approx(25.0) and base["a"]["n"] == 3
    np.testing.assert_allclose(base["a"]["ci"], [25 - half, 25 + half])
    assert base["diff"]["diff"] == pytest.approx(0.0)        # the same baseline in both
    # sim-pretrain at 50 %: A has trials 0 and 1 (trial 2 failed), B all three
    sim = _cell(data, "sim-pretrain", 0.5)
    assert (sim["a"]["n"], sim["b"]["n"]) == (2, 3)
    assert sim["b"]["mean"] == pytest.approx(np.mean(
        [ap_of("sim-pretrain", 0.5, t) + _shift(t) for t in range(3)]))
    # Δ_B − Δ_A: the Welch interval of B's paired differences against A's
    for fraction, trials_a in ((0.1, [0, 1, 2]), (0.5, [0, 1])):
        d = _delta(data, "sim-pretrain", fraction)
        d_a = [3.0 + 0.5 * t for t in trials_a]
        d_b = [3.0 + 0.5 * t + _shift(t) for t in range(3)]
        assert d["a"]["delta"] == pytest.approx(np.mean(d_a))
        assert d["b"]["delta"] == pytest.approx(np.mean(d_b))
        assert (d["a"]["n_pairs"], d["b"]["n_pairs"]) == (len(d_a), 3)
        ref = sps.ttest_ind(d_b, d_a, equal_var=False).confidence_interval(0.95)
        assert d["diff"]["diff"] == pytest.approx(np.mean(d_b) - np.mean(d_a))
        np.testing.assert_allclose(d["diff"]["ci"], [ref.low, ref.high], rtol=1e-9)
    # the tables say the same in words: Δ_B − Δ_A at 10 % is 2.25 with an interval above 0
    row = next(r for r in data["delta_table"]["rows"] if r[:2] == ["Sim Pretrain", "10 %"])
    assert row[-1].startswith("+2.2 [+0.7, +3.8]")
    json.dumps(data, allow_nan=False)


def test_figures_draw_both_sweeps_and_the_difference_per_condition(sweeps):
    data = compare_data(*(load_sweep(s) for s in sweeps))
    means = [t["meta"] for t in data["figures"]["ap"]["data"] if t["meta"]["role"] == "mean"]
    assert [(m["condition"], m["sweep"]) for m in means] == [
        ("baseline", "a"), ("baseline", "b"), ("sim-pretrain", "a"), ("sim-pretrain", "b")]
    traces = data["figures"]["delta"]["data"]
    deltas = [t for t in traces if t["meta"]["role"] == "delta"]
    assert [t["meta"]["sweep"] for t in deltas] == ["a", "b"]
    (diff,) = [t for t in traces if t["meta"]["role"] == "delta-diff"]
    assert diff["y"] == pytest.approx([d["diff"]["diff"] for d in data["deltas"]])
    assert diff["error_y"]["array"] == pytest.approx(
        [d["diff"]["ci"][1] - d["diff"]["diff"] for d in data["deltas"]])


def test_what_only_one_sweep_ran_and_the_settings_that_differ(sweeps):
    data = compare_data(*(load_sweep(s) for s in sweeps))
    assert data["only"]["a"] == {"conditions": [], "fractions": ["100 %"], "cells": []}
    assert data["only"]["b"]["conditions"] == ["Sim-GT Pretrain"]
    assert data["only"]["b"]["fractions"] == ["25 %"]
    settings = {r[1]: r for r in data["settings"]["rows"]}
    for key in ("profile.sweep_seed", "datasets.real.path", "datasets.real.key",
                "provenance.git", "conditions", "fractions", "n_runs",
                "run seeds (runs.parquet: trial -> seed)"):
        assert key in settings, key
    assert settings["profile.sweep_seed"][2:] == ["(absent)", "1"]
    assert settings["datasets.real.path"][2:] == ['"/data/real"', '"/data/real2"']
    assert settings["provenance.git"][0] == "code"
    for same in ("metric", "trials", "datasets.sim.path", "provenance.versions.torch",
                 "created_at"):
        assert same not in settings, same
    n = data["settings"]
    assert n["n_compared"] - n["n_same"] == len(n["rows"]) and n["n_same"] > 10


def test_a_sweep_on_another_metric_is_compared_on_the_first_ones(sweeps):
    a, b = sweeps
    doc = json.loads((b / "sweep.json").read_text())
    doc["metric"] = "ap_bev_r40_iou05"
    (b / "sweep.json").write_text(json.dumps(doc))
    data = compare_data(load_sweep(a), load_sweep(b))
    assert data["metric"] == METRIC
    assert any("recomputed from its runs.parquet" in w for w in data["warnings"])
    assert _cell(data, "baseline", 0.1)["b"]["mean"] == pytest.approx(25.0)   # 3D, not BEV


def test_cli_writes_the_comparison_page(sweeps, tmp_path):
    a, b = sweeps
    out = tmp_path / "cmp.html"
    res = _cli(a, b, "--out", out)
    assert res.exit_code == 0, res.output
    assert res.output.strip() == str(out)
    page = out.read_text()
    doc = json.loads(re.search(r'<script type="application/json" id="compare-data">(.*?)'
                               r"</script>", page, re.S).group(1))
    assert (doc["a"]["name"], doc["b"]["name"]) == ("a", "b") and doc["kind"] == "comparison"
    assert "default-src &#x27;none&#x27;" in page and "connect-src &#x27;none&#x27;" in page


@pytest.mark.parametrize("args, says", [
    (("--serve",), "--serve shows one sweep live"),
    ((), "give --out FILE.html for the comparison page"),
])
def test_cli_two_sweeps_without_out_or_with_serve_is_refused(sweeps, args, says):
    res = _cli(*sweeps, *args)
    assert res.exit_code == 2 and says in res.output
    assert len(res.output.strip().splitlines()) == 1


def test_cli_refuses_three_sweeps_and_names_a_missing_one(sweeps, tmp_path):
    res = _cli(*sweeps, sweeps[0], "--out", tmp_path / "x.html")
    assert res.exit_code == 2 and "3 sweeps given" in res.output
    res = _cli(sweeps[0], tmp_path / "nope", "--out", tmp_path / "x.html")
    assert res.exit_code == 2 and "nope: no such sweep folder" in res.output
    assert not (tmp_path / "x.html").exists()
