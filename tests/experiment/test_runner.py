"""One training run of the sweep: the conditions differ only in the encoder; runs resume."""

from __future__ import annotations

import json

import pytest

from sim2radar.datasets import make_door_frames
from sim2radar.experiment import load_profile
from sim2radar.experiment.runner import (
    AP_COLUMNS,
    NonFiniteLoss,
    _check_finite,
    finetune_and_test,
    pretrain_encoder,
)


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    cfg = load_profile("smoke").detector_config("finetune")
    root = tmp_path_factory.mktemp("runner")
    sim = make_door_frames(8, seed=1, points_per_frame=300)
    real = make_door_frames(12, seed=2, points_per_frame=300)
    ckpt = pretrain_encoder(cfg, sim, root / "pretrain", seed=3, epochs=1)
    return {"cfg": cfg, "root": root, "train": real[:8], "test": real[8:], "ckpt": ckpt}


def _run(s, name, **kw):
    return finetune_and_test(s["cfg"], s["train"], s["test"], s["root"] / name, seed=7,
                             epochs=2, **kw)


def test_pretraining_is_done_once(setup):
    done = json.loads((setup["root"] / "pretrain" / "done.json").read_text())
    assert done["epochs"] == 1 and done["frames"] == 8
    again = pretrain_encoder(setup["cfg"], [], setup["root"] / "pretrain", seed=3, epochs=1)
    assert again == setup["ckpt"]          # found finished: no frames needed, nothing trained


def test_conditions_differ_only_in_the_encoder(setup):
    a = _run(setup, "base_a")
    b = _run(setup, "base_b")
    c = _run(setup, "pre", encoder_checkpoint=setup["ckpt"])
    assert set(AP_COLUMNS) <= set(a) and a["epochs"] == 2 and a["steps"] == 4
    assert a["history_loss"] == b["history_loss"]            # deterministic given the seed
    assert a["history_loss"] != c["history_loss"]            # the encoder changed the training


def test_a_killed_run_resumes_and_matches_an_uninterrupted_one(setup, monkeypatch):
    import sim2radar.detect.train as train_mod

    real_val = train_mod.validation_ap
    calls = []

    def killed_in_epoch_two(model, frames, *a, **k):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt("killed during epoch 2")
        return real_val(model, frames, *a, **k)

    monkeypatch.setattr(train_mod, "validation_ap", killed_in_epoch_two)
    with pytest.raises(KeyboardInterrupt):
        _run(setup, "killed", val_frames=setup["test"], val_every=1)
    epochs_run = []
    monkeypatch.setattr(train_mod, "validation_ap",
                        lambda m, f, *a, **k: epochs_run.append(1) or real_val(m, f, *a, **k))
    resumed = _run(setup, "killed", val_frames=setup["test"], val_every=1)
    assert len(epochs_run) == 1                       # only epoch 2 was trained again
    monkeypatch.setattr(train_mod, "validation_ap", real_val)
    whole = _run(setup, "whole", val_frames=setup["test"], val_every=1)
    assert resumed["history_loss"] == whole["history_loss"]
    assert resumed["history_val_epoch"] == whole["history_val_epoch"] == [1, 2]
    assert resumed["history_val_ap"] == whole["history_val_ap"]
    assert resumed["ap_3d_r40_iou03"] == whole["ap_3d_r40_iou03"]


def test_diverged_training_is_an_error():
    _check_finite([{"epoch": 1, "total": 1.0}], "x")
    with pytest.raises(NonFiniteLoss, match="epoch 2"):
        _check_finite([{"epoch": 1, "total": 1.0}, {"epoch": 2, "total": float("nan")}], "x")


def test_validation_points_are_capped_on_long_runs(setup):
    """A small fraction raised to many short epochs validates at most max_val_points times,
    evenly, and always at the last epoch."""
    s = setup
    row = finetune_and_test(s["cfg"], s["train"][:2], s["test"], s["root"] / "capped", seed=7,
                            epochs=7, val_frames=s["test"], val_every=1, max_val_points=3)
    assert row["history_val_epoch"] == [3, 6, 7]
    assert len(row["history_val_ap"]) == 3
