"""``python -m benchmarks training`` in its CI-sized form (issue #31): the demo model, two
steps, one round — the script runs on a CPU and its figures are coherent."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]


def test_the_training_benchmark_runs_ci_sized(capsys, monkeypatch):
    if torch.cuda.is_available():
        pytest.skip("on a GPU: run `python -m benchmarks training`")
    monkeypatch.syspath_prepend(str(ROOT))
    monkeypatch.setenv("SIM2RADAR_BENCH_PROFILES", "demo")
    monkeypatch.setenv("SIM2RADAR_BENCH_STEPS", "2")
    monkeypatch.setenv("SIM2RADAR_BENCH_ROUNDS", "1")
    sys.modules.pop("benchmarks.bench_training", None)
    from benchmarks import bench_training

    threads = torch.get_num_threads()
    res = bench_training.main()
    assert torch.get_num_threads() == threads       # the 1-thread row leaves the count alone
    out = capsys.readouterr().out
    assert "paper" not in res and res["steps"] == 2
    demo = res["demo"]
    # the parts add up to the step they were timed inside (medians of 2 steps: means)
    parts = demo["augment"] + demo["collate"] + demo["assign"] + demo["model"]
    assert all(demo[k] > 0 for k in ("augment", "assign", "model", "step"))
    assert parts == pytest.approx(demo["step"], rel=0.2)
    for w in (0, 1, 2):
        assert demo[f"workers_{w}"] > 0 and demo[f"wait_ms_{w}"] >= 0
    # the demo model's step is ~0.9 GFLOP (its convolutions, forward and backward) and cannot
    # beat the float32 floor that the device's own matrix-product rate sets
    assert 0.3 < demo["gflop"] < 3.0
    assert res["matmul_gflops"] > 0
    # (the rate is rounded to 0.1 GFLOP/s)
    assert demo["gflops"] == pytest.approx(demo["gflop"] / (demo["step"] / 1000), abs=0.06)
    assert 0 < demo["floor_ms"] < demo["step"]
    assert "float32 floor" in out
    if "demo_1_thread" in res:  # a CPU with a core to spare for the worker
        spare = res["demo_1_thread"]
        assert spare["workers_0"] > 0 and spare["workers_1"] > 0
        assert "a core spare for the worker" in out
