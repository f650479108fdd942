"""``python -m benchmarks gpu`` runs on a machine without CUDA (small sizes), so CI exercises the
script a GPU session will run (issue #31), and its figures are coherent."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_the_gpu_benchmark_runs_on_a_cpu(capsys, monkeypatch):
    import torch

    if torch.cuda.is_available():
        pytest.skip("on a GPU the benchmark takes minutes: run `python -m benchmarks gpu`")
    monkeypatch.syspath_prepend(str(ROOT))
    sys.modules.pop("benchmarks.bench_gpu", None)
    from benchmarks import bench_gpu

    res = bench_gpu.main()
    out = capsys.readouterr().out
    step = res["step"]["demo"]
    assert step["float32"] > 0 and step["auto_chooses"] in ("float32", "bfloat16")
    assert set(res["runs_per_device"]) == {1, 2}
    assert all(v["steps_per_s"] > 0 for v in res["runs_per_device"].values())
    grid = res["paper_grid"]
    # the paper's grid: 5 fractions x 5 trials x (baseline + sim-pretrain) + 25 pre-trainings
    assert grid["jobs"] == 75 and grid["steps"] > 100_000
    assert grid["best_runs"] in (1, 2) and grid["throughput_of"] == "demo"
    radar = res["radar"]
    assert radar["frame_s"] > radar["bare_s"] > 0 and radar["reference_frame_s"] > 0
    # without CUDA the frame is detected on the host; the torch chain ran on the CPU beside it
    assert radar["detection_device"] == "host" and radar["torch_device"] == "cpu"
    assert radar["frame_host_detection_s"] > 0 and radar["frame_torch_detection_s"] > 0
    assert radar["reference_device"] == "cpu" and "by torch on cpu" in out
    # the stages: the ray-traced frame's own timers add up to its total; the reference frame's
    # two synchronised halves each take time
    stages = radar["frame_stages_ms"]
    assert {"trace", "detect", "total"} <= set(stages)
    parts = sum(v for k, v in stages.items() if k != "total")
    assert parts <= stages["total"] * 1.05 and parts >= 0.5 * stages["total"]
    assert set(radar["reference_stages_ms"]) == {"synthesis", "processing"}
    assert all(v > 0 for v in radar["reference_stages_ms"].values())
    assert "reference frame's [ms" in out
    # a walking rig's frame, as the factory's are taken: more Doppler slabs to detect
    assert radar["walking_frame_s"] > radar["bare_s"] and "the rig walking at 1 m/s" in out
    assert radar["walking_frame_stages_ms"]["detect"] > 0
    assert "--runs-per-gpu auto would choose" in out and "paper grid: 75 jobs" in out
