"""Several training runs per GPU (issue #31): the choice rule, the measurement, the options."""

from __future__ import annotations

import pytest

from sim2radar.cli.experiment import sweep_flag
from sim2radar.experiment import load_profile, packing
from sim2radar.experiment.packing import aggregate_throughput, choose_runs, probe_runs
from sim2radar.tasks.experiment import cuda_devices, parse_runs_per_gpu


@pytest.mark.parametrize(("measured", "runs"), [
    ({1: 24.0, 2: 41.0, 4: 52.0, 8: 57.5}, 8),     # the H100 figures: 57.5 >= 1.1 x 52
    ({1: 24.0, 2: 41.0, 4: 52.0, 8: 56.0}, 4),     # +7.7 % is not worth 4 more processes
    ({1: 10.0, 2: 10.5, 4: 10.9}, 1),              # sharing does not pay: one at a time
    ({1: 10.0, 2: 20.0, 4: 19.0, 8: 21.5}, 2),     # 8 is not 10 % above the best (2)
])
def test_a_larger_count_only_for_ten_percent_more_aggregate_throughput(measured, runs):
    decision = choose_runs(measured)
    assert decision.runs == runs and decision.source == "probe"
    assert decision.seconds_per_step() == pytest.approx(runs / measured[runs])
    assert decision.to_dict()["steps_per_s"] == {str(k): v for k, v in measured.items()}


def _device(monkeypatch, curve, fails_at=None):
    """A fake device behind :func:`aggregate_throughput`: it reads ``curve``; returns the list
    of the counts asked for."""
    asked = []

    def measure(cfg, device, counts, steps):
        asked.extend(counts)
        if fails_at in counts:
            raise RuntimeError(f"runs-per-device probe ({fails_at} processes on cuda) failed "
                               "with exit status 1:\ntorch.OutOfMemoryError: CUDA out of memory")
        return {n: curve[n] for n in counts}
    monkeypatch.setattr(packing, "aggregate_throughput", measure)
    return asked


def test_auto_keeps_doubling_while_a_doubling_still_pays(monkeypatch):
    """The H100's curve was still rising at 8 runs (+62 % over 4): auto goes on to 16 and 32
    (the cap) and takes 16, as 32 adds under 10 %."""
    curve = {1: 61.8, 2: 86.1, 4: 126.4, 8: 205.1, 16: 300.0, 32: 310.0, 64: 400.0}
    asked = _device(monkeypatch, curve)
    per_n, note = probe_runs(None, "cuda")
    assert asked == [1, 2, 4, 8, 16, 32] and note == ""
    assert choose_runs(per_n).runs == 16
    # a curve flat from 4 to 8 asks for nothing more
    asked = _device(monkeypatch, {1: 24.0, 2: 41.0, 4: 52.0, 8: 56.0})
    assert set(probe_runs(None, "cuda")[0]) == {1, 2, 4, 8}
    assert asked == [1, 2, 4, 8]


def test_a_count_the_device_cannot_hold_ends_the_climb_and_is_said(monkeypatch):
    curve = {1: 61.8, 2: 86.1, 4: 126.4, 8: 205.1}
    asked = _device(monkeypatch, curve, fails_at=16)
    per_n, note = probe_runs(None, "cuda")
    assert per_n == curve and asked == [1, 2, 4, 8, 16]
    assert note.startswith("16 runs failed") and "out of memory" in note
    # decide_runs("auto") chooses among the measured counts and records why it stopped
    decision = packing.decide_runs(None, "cuda", "auto")
    assert decision.runs == 8 and "16 runs failed" in decision.reason


def test_aggregate_throughput_runs_concurrent_training_processes():
    cfg = load_profile("smoke").detector_config("finetune").with_updates(
        runtime={"amp": False, "num_threads": 1})
    per_n = aggregate_throughput(cfg, "cpu", (1, 2), steps=2)
    assert set(per_n) == {1, 2} and all(v > 0 for v in per_n.values())


def test_a_failing_probe_process_says_why():
    cfg = load_profile("smoke").detector_config("finetune")
    with pytest.raises(RuntimeError, match=r"probe \(1 processes on nonsense\) failed"):
        aggregate_throughput(cfg, "nonsense", (1,), steps=1)


def test_runs_per_gpu_option_values():
    assert parse_runs_per_gpu("auto") == "auto" and parse_runs_per_gpu(None) is None
    assert parse_runs_per_gpu("4") == 4 and parse_runs_per_gpu(2) == 2
    for bad in ("0", "-1", "two", "2.5", True):
        with pytest.raises(ValueError, match="runs per GPU must be a count") as err:
            parse_runs_per_gpu(bad)
        assert err.value.spelled(sweep_flag).startswith("--runs-per-gpu must be a count")


def test_runs_per_gpu_needs_a_cuda_device():
    with pytest.raises(ValueError, match="not a CUDA GPU; on a CPU give the number of "
                       "concurrent runs") as err:
        cuda_devices("cpu")
    assert "on a CPU give --workers" in err.value.spelled(sweep_flag)


def test_the_sweep_command_refuses_runs_per_gpu_on_a_cpu(tmp_path):
    from typer.testing import CliRunner

    from sim2radar.cli import app

    res = CliRunner().invoke(app, ["sweep", str(tmp_path / "sim"), str(tmp_path / "real"),
                                   "--device", "cpu", "--runs-per-gpu", "2",
                                   "--out", str(tmp_path / "sweeps"),
                                   "--store", str(tmp_path / "store")])
    assert res.exit_code == 2 and "not a CUDA GPU" in res.output, res.output
    assert not (tmp_path / "sweeps").exists()
