"""Training batches prepared ahead of the step (issue #31): the same batches bit for bit."""

from __future__ import annotations

import threading

import numpy as np
import pytest
import torch

from sim2radar.datasets import make_door_frames
from sim2radar.detect import batches as batches_mod
from sim2radar.detect.augment import build_gt_database
from sim2radar.detect.batches import epoch_batches
from sim2radar.detect.train import train
from sim2radar.experiment import load_profile


def _cfg():
    return load_profile("smoke").detector_config("finetune").with_updates(
        runtime={"amp": False, "progress": False, "device": "cpu"})


def _epoch(frames, cfg, prefetch, seed=3):
    mcfg = cfg.model
    db = build_gt_database(frames, mcfg.class_names, cfg.augmentation.min_points_in_gt)
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(frames))
    return list(epoch_batches(frames, order, 3, cfg.augmentation, mcfg, rng, db,
                              torch.device("cpu"), prefetch=prefetch))


def test_prefetched_batches_equal_the_ones_made_at_each_step():
    cfg = _cfg()
    frames = make_door_frames(10, seed=0, points_per_frame=300)
    now, ahead = _epoch(frames, cfg, 0), _epoch(frames, cfg, 3)
    assert [n for *_, n in now] == [3, 3, 3, 1]
    for (p0, g0, n0), (p1, g1, n1) in zip(now, ahead, strict=True):
        assert n0 == n1 and torch.equal(p0, p1) and torch.equal(g0, g1)


def test_training_with_prefetch_gives_the_same_run(tmp_path):
    cfg = _cfg()
    frames = make_door_frames(12, seed=1, points_per_frame=300)
    runs = {}
    for prefetch in (0, 2):
        res = train(cfg.with_updates(runtime={"prefetch_batches": prefetch}),
                    out_dir=tmp_path / f"p{prefetch}", frames=frames, epochs=2, seed=0)
        state = torch.load(res.checkpoint, map_location="cpu", weights_only=False)["model"]
        runs[prefetch] = ([{k: v for k, v in h.items() if "seconds" not in k}
                           for h in res.history], state)
    assert runs[0][0] == runs[2][0]                       # every loss, to the last bit
    assert all(torch.equal(runs[0][1][k], runs[2][1][k]) for k in runs[0][1])


def test_an_augmentation_error_reaches_the_loop_and_leaving_early_stops_the_thread(
        monkeypatch):
    cfg = _cfg()
    frames = make_door_frames(9, seed=2, points_per_frame=200)
    real, calls = batches_mod.augment_frame, []

    def flaky(frame, *args, **kwargs):
        calls.append(frame.frame_id)
        if len(calls) == 5:
            raise ValueError("a broken frame")
        return real(frame, *args, **kwargs)

    monkeypatch.setattr(batches_mod, "augment_frame", flaky)
    mcfg = cfg.model
    rng = np.random.default_rng(0)
    got = epoch_batches(frames, np.arange(9), 3, cfg.augmentation, mcfg, rng, None,
                        torch.device("cpu"), prefetch=2)
    assert next(got)[2] == 3                              # batch 0 is fine
    with pytest.raises(ValueError, match="a broken frame"):
        next(got)                                         # batch 1 holds the 5th frame
    monkeypatch.setattr(batches_mod, "augment_frame", real)
    early = epoch_batches(frames, np.arange(9), 1, cfg.augmentation, mcfg, rng, None,
                          torch.device("cpu"), prefetch=1)
    next(early)
    early.close()
    assert not any(t.name == "sim2radar-batches" and t.is_alive()
                   for t in threading.enumerate())
