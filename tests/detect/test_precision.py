"""``amp: auto`` decided by measurement (issue #31): the rule, the record, the probe."""

from __future__ import annotations

import json

import pytest
import torch

from sim2radar.detect import precision
from sim2radar.detect.config import DetectConfig
from sim2radar.experiment import load_profile


def _cfg(amp="auto") -> DetectConfig:
    return load_profile("smoke").detector_config("finetune").with_updates(runtime={"amp": amp})


def _fake_probe(monkeypatch, seconds: dict) -> list:
    calls = []

    def probe(cfg, device, dtype, steps=precision.PROBE_STEPS):
        name = "float32" if dtype is None else str(dtype).removeprefix("torch.")
        calls.append(name)
        return seconds[name]

    monkeypatch.setattr(precision, "probe_step_seconds", probe)
    monkeypatch.setattr("sim2radar.hardware.cpu_has_native_bf16", lambda: True)
    return calls


def test_fixed_amp_is_taken_as_it_is_without_a_probe(monkeypatch, tmp_path):
    calls = _fake_probe(monkeypatch, {})
    assert precision.decide_precision(_cfg(False), "cpu", table=tmp_path).amp is False
    on = precision.decide_precision(_cfg(True), "cpu", table=tmp_path)
    assert on.amp is True and on.dtype == "bfloat16" and on.source == "fixed"
    assert calls == [] and not list(tmp_path.iterdir())


def test_a_cpu_without_native_bf16_keeps_float32_by_the_table(monkeypatch, tmp_path):
    calls = _fake_probe(monkeypatch, {})
    monkeypatch.setattr("sim2radar.hardware.cpu_has_native_bf16", lambda: False)
    got = precision.decide_precision(_cfg(), "cpu", table=tmp_path)
    assert (got.amp, got.dtype, got.source) == (False, "float32", "table")
    assert calls == []


@pytest.mark.parametrize(("bf16_s", "amp"), [(0.90, True), (0.96, False), (1.20, False)])
def test_mixed_precision_only_when_at_least_five_percent_faster(monkeypatch, tmp_path, bf16_s,
                                                                amp):
    """The H100 case (bf16 slower than float32) keeps float32; a 4 % gain is not enough."""
    calls = _fake_probe(monkeypatch, {"float32": 1.0, "bfloat16": bf16_s})
    got = precision.decide_precision(_cfg(), "cpu", table=tmp_path)
    assert got.amp is amp and got.source == "probe" and sorted(calls) == ["bfloat16", "float32"]
    assert got.seconds_per_step == {"float32": 1.0, "bfloat16": bf16_s}
    assert got.dtype == ("bfloat16" if amp else "float32")
    # recorded: a later decision for this device and model reuses it without probing
    (record,) = tmp_path.iterdir()
    assert json.loads(record.read_text())["amp"] is amp
    again = precision.decide_precision(_cfg(), "cpu", table=tmp_path)
    assert again.source == "recorded" and again.amp is amp and len(calls) == 2
    # an estimate never probes
    assert precision.decide_precision(_cfg(), "cpu", probe=False).source == "rule"
    assert len(calls) == 2


def test_another_model_is_probed_on_its_own_and_a_bad_record_is_replaced(monkeypatch,
                                                                         tmp_path):
    calls = _fake_probe(monkeypatch, {"float32": 1.0, "bfloat16": 0.5})
    precision.decide_precision(_cfg(), "cpu", table=tmp_path)
    bigger = _cfg().with_updates(optimization={"batch_size": 2})
    precision.decide_precision(bigger, "cpu", table=tmp_path)
    assert len(calls) == 4 and len(list(tmp_path.iterdir())) == 2
    for f in tmp_path.iterdir():
        f.write_text("{not json")
    assert precision.decide_precision(_cfg(), "cpu", table=tmp_path).source == "probe"


def test_a_real_probe_times_the_model_in_both_precisions():
    cfg = _cfg()
    fp32 = precision.probe_step_seconds(cfg, "cpu", None, steps=2)
    bf16 = precision.probe_step_seconds(cfg, "cpu", torch.bfloat16, steps=2)
    assert 0 < fp32 < 30 and 0 < bf16 < 30
    assert precision.device_name("cpu").startswith("cpu:")


def test_the_device_name_does_not_follow_torchs_current_thread_count():
    """A training run sets torch's thread count (runtime.num_threads) and leaves it: the same
    sweep prepared again in that process must name the same device, or its recorded precision
    is not found and a timed probe may flip its runs' keys."""
    before = torch.get_num_threads()
    name = precision.device_name("cpu")
    try:
        torch.set_num_threads(1 if before > 1 else 2)
        assert precision.device_name("cpu") == name
    finally:
        torch.set_num_threads(before)
    assert precision.device_name("cpu", 3).endswith(":3 threads")


def test_only_a_decision_that_can_be_recorded_is_measured_and_a_known_one_is_kept(
        monkeypatch, tmp_path):
    """Without a table the decision is the rule (two calls always agree: a sweep's settings
    and run keys cannot flip with timing noise); a sweep's earlier decision for this device
    wins over the table."""
    calls = _fake_probe(monkeypatch, {"float32": 1.0, "bfloat16": 2.0})
    first = precision.decide_precision(_cfg(), "cpu")
    assert first.source == "rule" and first.amp is True and calls == []
    known = precision.PrecisionDecision(False, "float32",
                                        precision.device_name("cpu", _cfg().runtime.num_threads),
                                        "probe", {"float32": 1.0}, 4, "earlier").to_dict()
    got = precision.decide_precision(_cfg(), "cpu", table=tmp_path, known=known)
    assert (got.amp, got.source) == (False, "recorded") and calls == []
    # a decision nothing measured is kept with its own source: "recorded" means figures
    table = dict(known, source="table", seconds_per_step={}, steps=0)
    kept = precision.decide_precision(_cfg(), "cpu", table=tmp_path, known=table)
    assert (kept.amp, kept.source, kept.seconds_per_step) == (False, "table", {})
    elsewhere = dict(known, device="cuda:Some GPU")
    assert precision.decide_precision(_cfg(), "cpu", table=tmp_path,
                                      known=elsewhere).source == "probe"


def test_stored_decisions_keep_their_key_when_only_the_order_of_draws_is_new():
    """The table's key (model, augmentation, batch) of the default config as written before
    ``augmentation.random_draws`` existed (issue #31): the decisions measured then still apply."""
    assert precision._digest(DetectConfig()) == "57b1173319073964"
