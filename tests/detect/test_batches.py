"""Training batches made in DataLoader workers (issue #31): each batch is a function of (seed,
epoch, batch index) alone — the same bit for bit for 0, 1 and 2 workers, under fork and spawn,
and across a resumed run."""

from __future__ import annotations

import multiprocessing

import numpy as np
import pytest
import torch

from sim2radar.datasets import make_door_frames
from sim2radar.detect import batches as batches_mod
from sim2radar.detect.augment import augment_frame, build_gt_database
from sim2radar.detect.batches import TrainingBatches, collate, resolve_loader_workers
from sim2radar.detect.config import DetectConfig, RuntimeConfig
from sim2radar.detect.train import train
from tests.detect.conftest import small_config


def _cfg():
    return small_config(optimization=dict(batch_size=3, epochs=2))


def _batches(frames, cfg, workers, epochs=(0, 1), seed=3, epochs_total=None, **kw):
    """Every batch of ``epochs`` as made with ``workers`` workers (``epochs_total``: the run's
    epoch count, streamed across epochs; None: one epoch at a time)."""
    mcfg = cfg.model
    db = build_gt_database(frames, mcfg.class_names, cfg.augmentation.min_points_in_gt)
    with TrainingBatches(frames, 3, cfg.augmentation, mcfg, db, seed, "cpu", workers=workers,
                         epochs=epochs_total, **kw) as tb:
        return [list(tb.epoch(e)) for e in epochs]


def _same(a, b) -> bool:
    return all(len(x) == len(y) and all(
        n0 == n1 and torch.equal(p0, p1) and torch.equal(g0, g1)
        for (p0, g0, n0), (p1, g1, n1) in zip(x, y, strict=True))
        for x, y in zip(a, b, strict=True))


def test_batches_follow_the_stated_order_of_draws():
    """Batch k of epoch e: frames default_rng([s, e]).permutation(N)[kB:(k+1)B], augmented in
    turn with default_rng(SeedSequence([s, e]).spawn(k + 1)[k]) (the module docstring)."""
    cfg = _cfg()
    frames = make_door_frames(7, seed=0, points_per_frame=300)
    db = build_gt_database(frames, cfg.model.class_names, cfg.augmentation.min_points_in_gt)
    got = _batches(frames, cfg, 0, epochs=(2,), seed=5)[0]
    order = np.random.default_rng([5, 2]).permutation(7)
    children = np.random.SeedSequence([5, 2]).spawn(3)
    assert [n for *_, n in got] == [3, 3, 1]
    for k, (pts, gt, _) in enumerate(got):
        rng = np.random.default_rng(children[k])
        aug = [augment_frame(frames[i], cfg.augmentation, rng, cfg.model.point_cloud_range_m, db)
               for i in order[3 * k:3 * k + 3]]
        ref_pts, ref_gt = collate([a[0] for a in aug], [a[1] for a in aug],
                                  [a[2] for a in aug], cfg.model.class_names)
        assert torch.equal(pts, ref_pts) and torch.equal(gt, ref_gt)
    # GT sampling pasted doors: the draws did something, and differ between batches
    assert got[0][1].shape[1] > 1


def test_batches_are_the_same_for_0_1_and_2_workers():
    cfg = _cfg()
    frames = make_door_frames(10, seed=0, points_per_frame=300)
    made = {w: _batches(frames, cfg, w) for w in (0, 1, 2)}
    assert [n for *_, n in made[0][0]] == [3, 3, 3, 1]
    assert _same(made[0], made[1]) and _same(made[0], made[2])
    # the epochs differ (another order, other draws): the comparison is not vacuous
    assert not torch.equal(made[0][0][0][0], made[0][1][0][0])


def test_spawned_workers_make_the_same_batches():
    """Under ``spawn`` the frames and the GT database are pickled to the worker once."""
    cfg = _cfg()
    frames = make_door_frames(5, seed=4, points_per_frame=200)
    assert _same(_batches(frames, cfg, 0, epochs=(1,)),
                 _batches(frames, cfg, 1, epochs=(1,), context="spawn"))


def test_training_with_workers_gives_the_same_run_and_resumes_exactly(tmp_path, monkeypatch):
    import sim2radar.detect.train as tr

    cfg = _cfg()
    frames = make_door_frames(7, seed=1, points_per_frame=300)
    after_one, real_save = {}, tr._save

    def spy(path, payload):                 # keep the last.pt a kill after epoch 1 would leave
        real_save(path, payload)
        if path.name == "last.pt" and payload["epoch"] == 1:
            after_one[path.parent.name] = torch.load(path, weights_only=True)

    monkeypatch.setattr(tr, "_save", spy)
    runs = {}
    for w in (0, 2):
        res = train(cfg.with_updates(runtime={"loader_workers": w, "last_every_s": 0}),
                    out_dir=tmp_path / f"w{w}", frames=frames, seed=0)
        runs[w] = (_losses(res.history), torch.load(res.checkpoint, weights_only=True)["model"])
    assert runs[0][0] == runs[2][0]                       # every loss, to the last bit
    assert all(torch.equal(runs[0][1][k], runs[2][1][k]) for k in runs[0][1])

    # the 2-worker run interrupted after epoch 1, resumed with one worker: the same run again
    (tmp_path / "resumed").mkdir()
    torch.save(after_one["w2"], tmp_path / "resumed" / "last.pt")
    res = train(cfg.with_updates(runtime={"loader_workers": 1}), out_dir=tmp_path / "resumed",
                frames=frames, seed=0, resume=True)
    assert _losses(res.history) == runs[0][0]
    state = torch.load(res.checkpoint, weights_only=True)["model"]
    assert all(torch.equal(state[k], runs[0][1][k]) for k in state)


def _losses(history):
    return [{k: v for k, v in h.items() if "seconds" not in k} for h in history]


def test_a_worker_error_reaches_the_loop_and_close_stops_the_workers(monkeypatch):
    cfg = _cfg()
    frames = make_door_frames(9, seed=2, points_per_frame=200)
    real = batches_mod.augment_frame
    bad = frames[4].frame_id

    def flaky(frame, *args, **kwargs):
        if frame.frame_id == bad:
            raise ValueError("a broken frame")
        return real(frame, *args, **kwargs)

    monkeypatch.setattr(batches_mod, "augment_frame", flaky)   # fork: the workers inherit it
    order = list(np.random.default_rng([0, 0]).permutation(9))
    k_bad = order.index(4) // 3
    tb = TrainingBatches(frames, 3, cfg.augmentation, cfg.model, None, 0, "cpu", workers=1,
                         context="fork")
    got = tb.epoch(0)
    for _ in range(k_bad):
        assert next(got)[2] == 3
    with pytest.raises(ValueError, match="a broken frame"):
        next(got)
    workers = list(tb._loader._iterator._workers)
    assert workers and all(w.is_alive() for w in workers)    # persistent
    tb.close()
    assert not any(w.is_alive() for w in workers)
    assert not [p for p in multiprocessing.active_children() if p in workers]
    with pytest.raises(RuntimeError, match="closed"):
        next(tb.epoch(1))


def test_worker_count_setting():
    assert resolve_loader_workers("auto", torch.device("cpu")) == 0
    assert resolve_loader_workers("auto", torch.device("cuda")) >= 1
    assert resolve_loader_workers(3, torch.device("cpu")) == 3
    assert RuntimeConfig().loader_workers == "auto"
    with pytest.raises(ValueError, match="loader_workers"):
        RuntimeConfig(loader_workers=-1)
    for bad in ("many", True):
        with pytest.raises(ValueError, match="loader_workers"):
            RuntimeConfig(loader_workers=bad)


def test_old_prefetch_setting_loads_with_a_warning_and_is_not_written():
    with pytest.warns(FutureWarning, match="prefetch_batches is deprecated"):
        cfg = DetectConfig.model_validate({"runtime": {"prefetch_batches": 1}})
    assert "prefetch_batches" not in cfg.model_dump(mode="json")["runtime"]
    assert DetectConfig.model_validate({"runtime": {"prefetch_batches": None}}).runtime \
        .loader_workers == "auto"


def test_a_run_from_before_the_new_draws_is_not_resumed(tmp_path):
    cfg = _cfg()
    frames = make_door_frames(3, seed=6, points_per_frame=200)
    res = train(cfg, out_dir=tmp_path / "run", frames=frames, seed=0, epochs=1)
    ckpt = torch.load(res.checkpoint, weights_only=True)
    assert ckpt["config"]["augmentation"]["random_draws"] == "per_batch"
    del ckpt["config"]["augmentation"]["random_draws"]   # as written before issue #31
    torch.save(ckpt, res.checkpoint)
    with pytest.raises(ValueError, match="before issue #31"):
        train(cfg, out_dir=tmp_path / "run", frames=frames, seed=0, epochs=1, resume=True)


@pytest.mark.parametrize("workers", [0, 2])
def test_a_run_long_stream_gives_the_per_epoch_batches(workers):
    """Told the run's epoch count, the batches stream across epoch boundaries (the workers
    prepare the next epoch's first batches during this one's last steps): the same batches as
    one epoch at a time, also when the run starts late (a resume), revisits an epoch, or
    leaves one unfinished."""
    cfg = _cfg()
    frames = make_door_frames(7, seed=2, points_per_frame=250)
    per_epoch = _batches(frames, cfg, 0, epochs=(0, 1, 2, 3))
    assert _same(_batches(frames, cfg, workers, epochs=(0, 1, 2, 3), epochs_total=4), per_epoch)
    assert _same(_batches(frames, cfg, workers, epochs=(2, 3), epochs_total=4), per_epoch[2:])
    mcfg = cfg.model
    db = build_gt_database(frames, mcfg.class_names, cfg.augmentation.min_points_in_gt)
    with TrainingBatches(frames, 3, cfg.augmentation, mcfg, db, 3, "cpu", workers=workers,
                         epochs=4) as tb:
        first = tb.epoch(0)
        next(first)                     # epoch 0 left after one batch
        assert _same([list(tb.epoch(1)), list(tb.epoch(1)), list(tb.epoch(3))],
                     [per_epoch[1], per_epoch[1], per_epoch[3]])
