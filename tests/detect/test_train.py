"""Training end to end: overfitting, determinism + resume, encoder transfer (the only
difference between conditions), the epoch hook and validation AP, evaluation."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from sim2radar.datasets import make_door_frames, write_synthetic_dataset
from sim2radar.detect import PointPillars
from sim2radar.detect.model import ENCODER_MODULES
from sim2radar.detect.train import (
    evaluate_checkpoint,
    load_checkpoint,
    load_encoder_from,
    predict_frames,
    seeded_model,
    train,
    validation_ap,
)
from sim2radar.evaluate import evaluate_detections
from tests.detect.conftest import small_config

NO_AUG = dict(gt_sampling=False, random_flip_x=False, rotation_range_rad=(0.0, 0.0),
              scale_range=(1.0, 1.0))


def test_overfits_a_few_door_frames(tmp_path):
    """6 synthetic frames (1,000 points, 1-3 doors each), 60 steps: AP3D@0.5 (R40) >= 90 %."""
    frames = make_door_frames(6, seed=0, points_per_frame=1000)
    cfg = small_config(optimization=dict(batch_size=3, epochs=30), augmentation=NO_AUG)
    res = train(cfg, out_dir=tmp_path / "run", frames=frames)
    assert res.history[-1]["total"] < 0.2 * res.history[0]["total"]
    model, _ = load_checkpoint(res.checkpoint, "cpu")
    dets = predict_frames(model, frames)
    # ~12 doors: exact recall positions (the devkit's AP is biased low below 41 boxes)
    ap = evaluate_detections([f.boxes for f in frames], [d.boxes.numpy() for d in dets],
                             [d.scores.numpy() for d in dets], thresholds="all")
    assert ap["3d_r40@0.3"] >= 90.0, ap
    assert ap["3d_r40@0.5"] >= 90.0, ap
    # detections land on the doors: centre error well under a pillar's 0.1 m
    for f, d in zip(frames, dets, strict=True):
        err = np.linalg.norm(f.boxes[:, None, :3] - d.boxes.numpy()[None, :, :3], axis=2)
        assert err.min(axis=1).max() < 0.1


def _losses(history):
    return [{k: v for k, v in h.items() if k != "seconds"} for h in history]


def test_same_seed_same_run_and_resume_continues_exactly(tmp_path):
    frames = make_door_frames(4, seed=1, points_per_frame=500)
    cfg = small_config(optimization=dict(batch_size=2, epochs=2))
    full = train(cfg, out_dir=tmp_path / "full", frames=frames, seed=3)
    again = train(cfg, out_dir=tmp_path / "again", frames=frames, seed=3)
    assert _losses(full.history) == _losses(again.history)
    other = train(cfg, out_dir=tmp_path / "other", frames=frames, seed=4)
    assert _losses(other.history) != _losses(full.history)

    # a run interrupted after epoch 1 (its last.pt), resumed to the end
    state = _state_after_epochs(cfg, frames, 3, 1, tmp_path / "tmp")
    assert state["epoch"] == 1
    resumed_dir = tmp_path / "resumed"
    resumed_dir.mkdir()
    torch.save(state, resumed_dir / "last.pt")
    res = train(cfg, out_dir=resumed_dir, frames=frames, seed=3, resume=True)
    assert _losses(res.history) == _losses(full.history)
    final = torch.load(full.checkpoint, weights_only=False)["model"]
    resumed = torch.load(res.checkpoint, weights_only=False)["model"]
    for k, v in final.items():
        torch.testing.assert_close(resumed[k], v, rtol=0, atol=0)
    with pytest.raises(ValueError, match="cannot resume"):
        train(cfg, out_dir=resumed_dir, frames=frames, seed=4, resume=True)


def _state_after_epochs(cfg, frames, seed, n, out_dir, **kw):
    """Checkpoint of a ``cfg`` run interrupted after ``n`` epochs (the last.pt it left)."""
    import sim2radar.detect.train as tr

    saved = []
    orig = tr._save

    def spy(path, payload):
        orig(path, payload)
        if path.name == "last.pt":
            saved.append(torch.load(path, weights_only=False))

    tr._save = spy
    try:  # last.pt after every epoch, whatever the epoch's length
        train(cfg.with_updates(runtime={"last_every_s": 0}), out_dir=out_dir, frames=frames,
              seed=seed, **kw)
    finally:
        tr._save = orig
    return saved[n - 1]


def test_last_checkpoint_is_written_when_due_and_a_killed_run_resumes_from_it(tmp_path,
                                                                              monkeypatch):
    """``runtime.last_every_s``: last.pt after the first epoch, at every epoch checkpoint and at
    the end, not between (none is due within an hour); an epoch checkpoint holds the same
    bytes as that last.pt. A run killed in epoch 4 resumes from epoch 3 to the uninterrupted
    run's weights, bit for bit."""
    import sim2radar.detect.train as tr

    frames = make_door_frames(4, seed=1, points_per_frame=300)
    cfg = small_config(optimization=dict(batch_size=2, epochs=5),
                       runtime=dict(last_every_s=3600.0, checkpoint_every=3, keep_checkpoints=5))
    written, real_save = [], tr._save

    def spy(path, payload):
        real_save(path, payload)
        written.append((path.name, payload["epoch"]))

    monkeypatch.setattr(tr, "_save", spy)
    full = train(cfg, out_dir=tmp_path / "full", frames=frames, seed=3)
    assert written == [("last.pt", 1), ("last.pt", 3), ("last.pt", 5)]
    assert sorted(p.name for p in (tmp_path / "full").glob("epoch_*.pt")) == ["epoch_3.pt",
                                                                             "epoch_5.pt"]
    assert (tmp_path / "full" / "epoch_5.pt").read_bytes() == full.checkpoint.read_bytes()

    def killed_in_epoch_4(epoch, model):
        if epoch == 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train(cfg, out_dir=tmp_path / "killed", frames=frames, seed=3,
              on_epoch_end=killed_in_epoch_4)
    assert torch.load(tmp_path / "killed" / "last.pt", weights_only=False)["epoch"] == 3
    res = train(cfg, out_dir=tmp_path / "killed", frames=frames, seed=3, resume=True)
    assert [{k: v for k, v in h.items() if k != "hook_seconds"} for h in _losses(res.history)] \
        == _losses(full.history)
    final = torch.load(full.checkpoint, weights_only=False)["model"]
    resumed = torch.load(res.checkpoint, weights_only=False)["model"]
    assert all(torch.equal(resumed[k], v) for k, v in final.items())


def test_a_truncated_last_checkpoint_is_quarantined_and_the_run_resumes_from_an_epoch_one(
        tmp_path):
    """A killed copy or write leaves last.pt truncated: train(resume=True) moves it into
    quarantine/, resumes from the newest epoch_<n>.pt that loads and ends exactly where an
    uninterrupted run ends; with no good checkpoint at all it starts from scratch."""
    frames = make_door_frames(4, seed=1, points_per_frame=400)
    cfg = small_config(optimization=dict(batch_size=2, epochs=4),
                       runtime=dict(checkpoint_every=1, keep_checkpoints=3))
    full = train(cfg, out_dir=tmp_path / "full", frames=frames, seed=3)
    run = tmp_path / "run"
    first = train(cfg, out_dir=run, frames=frames, seed=3)      # keeps epoch_2, 3 and 4
    for name in ("last.pt", "epoch_4.pt"):                      # truncated copies
        (run / name).write_bytes((run / name).read_bytes()[:700])
    (run / "epoch_3.pt").write_bytes(b"not a zip")
    res = train(cfg, out_dir=run, frames=frames, seed=3, resume=True)
    assert _losses(res.history) == _losses(full.history)
    # resumed from epoch_2.pt: epochs 1-2 are the first run's own records (their timings too)
    assert res.history[:2] == first.history[:2] and res.history[2:] != first.history[2:]
    quarantined = sorted(p.name.split(".pt")[0] for p in (run / "quarantine").iterdir())
    assert quarantined == ["epoch_3", "epoch_4", "last"]
    torch.testing.assert_close(torch.load(res.checkpoint, weights_only=False)["model"],
                               torch.load(full.checkpoint, weights_only=False)["model"])
    # nothing loads: from scratch, the same run
    for p in run.glob("*.pt"):
        p.write_bytes(b"")
    again = train(cfg, out_dir=run, frames=frames, seed=3, resume=True)
    assert _losses(again.history) == _losses(full.history)


def test_encoder_transfer_loads_encoder_only(tmp_path):
    frames = make_door_frames(4, seed=2, points_per_frame=500)
    cfg = small_config(optimization=dict(batch_size=2, epochs=1))
    pre = train(cfg, out_dir=tmp_path / "pre", frames=frames, seed=0)
    ckpt = torch.load(pre.checkpoint, weights_only=False)["model"]

    torch.manual_seed(123)
    model = PointPillars(cfg.model)
    fresh_head = {k: v.clone() for k, v in model.state_dict().items()
                  if k.startswith("dense_head")}
    loaded = load_encoder_from(model, pre.checkpoint)
    state = model.state_dict()
    assert loaded and all(k.split(".")[0] in ENCODER_MODULES for k in loaded)
    for k in loaded:  # encoder identical to the checkpoint, BN statistics included
        torch.testing.assert_close(state[k], ckpt[k], rtol=0, atol=0)
    for k, v in fresh_head.items():  # head untouched by the load: still its fresh init ...
        torch.testing.assert_close(state[k], v, rtol=0, atol=0)
    # ... which differs from the pre-trained head (weights moved in training)
    assert not torch.equal(state["dense_head.conv_box.weight"], ckpt["dense_head.conv_box.weight"])
    # and the class-prior init of a fresh head
    assert torch.allclose(state["dense_head.conv_cls.bias"],
                          torch.full_like(state["dense_head.conv_cls.bias"], -np.log(99)))

    # through train(): the run records what it loaded and trains from there
    fine = train(cfg, out_dir=tmp_path / "fine", frames=frames, init_encoder_from=pre.checkpoint)
    hist = json.loads((tmp_path / "fine" / "history.json").read_text())
    assert sorted(hist["encoder_loaded"]) == sorted(loaded)
    assert torch.load(fine.checkpoint, weights_only=False)["encoder_from"] == str(pre.checkpoint)


def test_encoder_lr_scale_moves_the_encoder_less_and_the_head_the_same(tmp_path):
    """Discriminative fine-tuning: at encoder_lr_scale 0.1 the encoder's first AdamW steps are
    a tenth of those at 1.0 (Adam's first step is lr * sign(grad) per weight, so the ratio is
    exact up to the clipped gradients' sign), the head's the same; the schedule's peak per
    group is recorded in the optimiser."""
    frames = make_door_frames(4, seed=2, points_per_frame=500)
    # lr 0.1: first steps of lr / div_factor = 0.01, far above float32's resolution at the
    # weights' magnitude (at 0.003 the rounding of w + step blurs the ratio by ~15 %)
    cfg = small_config(optimization=dict(batch_size=4, epochs=1, lr=0.1))
    pre = train(cfg, out_dir=tmp_path / "pre", frames=frames, seed=0)

    def moved(scale):
        c = cfg.with_updates(optimization={"encoder_lr_scale": scale, "weight_decay": 0.0})
        res = train(c, out_dir=tmp_path / f"s{scale}", frames=frames, seed=1,
                    init_encoder_from=pre.checkpoint)
        after = torch.load(res.checkpoint, weights_only=False)
        torch.manual_seed(1)
        start = PointPillars(cfg.model)
        load_encoder_from(start, pre.checkpoint)
        s0 = start.state_dict()
        delta = {part: float(sum((after["model"][k].float() - s0[k].float()).abs().sum()
                                 for k, _ in start.named_parameters()
                                 if (k.split(".")[0] in ENCODER_MODULES) == (part == "enc")))
                 for part in ("enc", "head")}
        groups = after["optimizer"]["param_groups"]
        return delta, [g["max_lr"] for g in groups]

    full, lr_full = moved(1.0)
    low, lr_low = moved(0.1)
    assert lr_full == [cfg.optimization.lr]
    assert lr_low == pytest.approx([0.1 * cfg.optimization.lr, cfg.optimization.lr])
    assert low["enc"] == pytest.approx(0.1 * full["enc"], rel=0.02)
    assert low["head"] == pytest.approx(full["head"], rel=0.02)
    with pytest.raises(ValueError, match="encoder_lr_scale"):
        cfg.with_updates(optimization={"encoder_lr_scale": 0.0})


def test_train_and_evaluate_from_a_dataset_on_disk(tmp_path):
    root = tmp_path / "data"
    write_synthetic_dataset(root, n_train=4, n_val=1, n_test=3, seed=5, points_per_frame=500)
    cfg = small_config(data=dict(root=root), optimization=dict(batch_size=2, epochs=1))
    res = train(cfg, out_dir=tmp_path / "run")
    assert res.steps == 2 and (tmp_path / "run" / "epoch_1.pt").is_file()
    ap = evaluate_checkpoint(res.checkpoint, split="test")
    assert ap["frames"] == 3 and 0.0 <= ap["3d_r11@0.3"] <= 100.0
    assert {"3d_r11@0.3", "3d_r40@0.3", "bev_r11@0.5", "bev_r40@0.5"} <= set(ap)
    # a model expecting 5 point features refuses 4-column data with a clear message
    bad = cfg.with_updates(model=dict(num_point_features=5))
    with pytest.raises(ValueError, match="num_point_features"):
        train(bad, out_dir=tmp_path / "bad")


def test_one_cycle_schedule_matches_openpcdet(tmp_path):
    """lr rises from lr/10 to lr over 40 % of the steps, then decays to lr/1e5."""
    frames = make_door_frames(2, seed=3, points_per_frame=300)
    cfg = small_config(optimization=dict(batch_size=1, epochs=10),
                       model=dict(layer_nums=(0, 0, 0), num_filters=(8, 8, 8),
                                  num_upsample_filters=(8, 8, 8)))
    res = train(cfg, out_dir=tmp_path / "run", frames=frames)
    lrs = [h["lr"] for h in res.history]  # lr of each epoch's last step (steps 1, 3, ..., 19)
    peak = int(np.argmax(lrs))
    assert lrs[peak] == pytest.approx(0.003, rel=0.05) and 3 <= peak <= 4
    assert all(a < b for a, b in zip(lrs[:peak], lrs[1:peak + 1], strict=True))
    assert all(a > b for a, b in zip(lrs[peak:-1], lrs[peak + 1:], strict=True))
    assert lrs[-1] < 3e-5


def test_the_multi_tensor_update_trains_the_weights_of_the_per_parameter_loop(tmp_path,
                                                                            monkeypatch):
    """train() asks AdamW for its multi-tensor (foreach) update on every device: on a CPU the
    same arithmetic as the per-parameter loop, bit for bit (two parameter groups, the one-cycle
    schedule's moving betas, gradient clipping), so runs trained before it stay valid."""
    frames = make_door_frames(4, seed=5, points_per_frame=300)
    cfg = small_config(optimization=dict(batch_size=2, epochs=2, encoder_lr_scale=0.1))
    fast = train(cfg, out_dir=tmp_path / "foreach", frames=frames)
    real = torch.optim.AdamW

    def per_parameter(*args, **kwargs):
        assert kwargs.pop("foreach") is True
        return real(*args, foreach=False, **kwargs)

    monkeypatch.setattr(torch.optim, "AdamW", per_parameter)
    loop = train(cfg, out_dir=tmp_path / "loop", frames=frames)
    a = load_checkpoint(fast.checkpoint)[0].state_dict()
    b = load_checkpoint(loop.checkpoint)[0].state_dict()
    start = seeded_model(cfg.model, cfg.seed).state_dict()
    assert a.keys() == b.keys()
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert any(not torch.equal(a[k], start[k]) for k in a)  # it trained


@pytest.mark.gpu
def test_trains_and_predicts_on_cuda_with_amp(tmp_path):
    frames = make_door_frames(4, seed=4, points_per_frame=500)
    cfg = small_config(optimization=dict(batch_size=2, epochs=2),
                       runtime=dict(device="cuda", amp=True, progress=False))
    res = train(cfg, out_dir=tmp_path / "run", frames=frames,
                on_epoch_end=lambda e, m: {"val_ap": validation_ap(m, frames)})
    model, _ = load_checkpoint(res.checkpoint, "cuda")
    dets = predict_frames(model, frames)
    assert len(dets) == 4 and np.isfinite(res.history[-1]["total"])
    assert all(0.0 <= h["val_ap"] <= 100.0 for h in res.history)


def _no_time(history):
    return [{k: v for k, v in h.items() if k not in ("seconds", "hook_seconds")}
            for h in history]


def test_epoch_hook_fields_are_saved_and_survive_resume(tmp_path):
    frames = make_door_frames(4, seed=5, points_per_frame=500)
    cfg = small_config(optimization=dict(batch_size=2, epochs=3))
    calls = []

    def hook(epoch, model):
        calls.append((epoch, model.training))  # must find the model in train mode
        model.eval()  # a careless hook: train() must switch back
        if epoch == 1:
            return None  # nothing recorded this epoch
        return {"val_ap": validation_ap(model, frames), "tag": f"e{epoch}"}

    full = train(cfg, out_dir=tmp_path / "full", frames=frames, seed=3, on_epoch_end=hook)
    assert calls == [(1, True), (2, True), (3, True)]  # back in train mode after each hook
    assert "val_ap" not in full.history[0] and full.history[0]["hook_seconds"] >= 0
    for rec in full.history[1:]:
        assert 0.0 <= rec["val_ap"] <= 100.0 and rec["tag"] == f"e{rec['epoch']}"
        assert rec["seconds"] >= rec["hook_seconds"] > 0
    # in the checkpoint and history.json
    ckpt = torch.load(full.checkpoint, weights_only=False)
    assert [h.get("val_ap") for h in ckpt["history"]] == [h.get("val_ap") for h in full.history]
    saved = json.loads((tmp_path / "full" / "history.json").read_text())["history"]
    assert saved[2]["val_ap"] == pytest.approx(full.history[2]["val_ap"])

    # the hook cannot change training: same losses and weights without it
    plain = train(cfg, out_dir=tmp_path / "plain", frames=frames, seed=3)
    assert _losses(plain.history) == [{k: v for k, v in h.items()
                                       if k not in ("seconds", "hook_seconds", "val_ap", "tag")}
                                      for h in full.history]

    # resumed after epoch 2: the hook runs for epoch 3 only; epoch 2's val_ap comes back from
    # the checkpoint, and the history equals the uninterrupted run's
    state = _state_after_epochs(cfg, frames, 3, 2, tmp_path / "tmp", on_epoch_end=hook)
    resumed_dir = tmp_path / "resumed"
    resumed_dir.mkdir()
    torch.save(state, resumed_dir / "last.pt")
    calls.clear()
    res = train(cfg, out_dir=resumed_dir, frames=frames, seed=3, resume=True, on_epoch_end=hook)
    assert calls == [(3, True)]
    assert _no_time(res.history) == _no_time(full.history)


def test_epoch_hook_return_is_checked(tmp_path):
    frames = make_door_frames(2, seed=6, points_per_frame=300)
    cfg = small_config(optimization=dict(batch_size=2, epochs=1))
    with pytest.raises(ValueError, match="'total'"):
        train(cfg, out_dir=tmp_path / "a", frames=frames, on_epoch_end=lambda e, m: {"total": 1})
    with pytest.raises(TypeError, match="dict or None"):
        train(cfg, out_dir=tmp_path / "b", frames=frames, on_epoch_end=lambda e, m: 41.2)
    with pytest.raises(TypeError, match="'curve'"):
        train(cfg, out_dir=tmp_path / "c", frames=frames,
              on_epoch_end=lambda e, m: {"curve": [1, 2]})


def test_validation_ap_matches_the_protocol_and_restores_the_mode(tmp_path):
    frames = make_door_frames(6, seed=7, points_per_frame=800)
    cfg = small_config(optimization=dict(batch_size=3, epochs=4), augmentation=NO_AUG)
    res = train(cfg, out_dir=tmp_path / "run", frames=frames)
    model, _ = load_checkpoint(res.checkpoint, "cpu")
    dets = predict_frames(model, frames)
    ref = evaluate_detections([f.boxes for f in frames], [d.boxes.numpy() for d in dets],
                              [d.scores.numpy() for d in dets])
    model.train()
    for iou, rp in ((0.3, 40), (0.5, 11)):
        assert validation_ap(model, frames, iou=iou, recall_points=rp) == pytest.approx(
            ref[f"3d_r{rp}@{iou}"])
    assert model.training  # mode restored
    model.eval()
    exact = validation_ap(model, frames, thresholds="all")
    assert not model.training
    # ~12 doors: the devkit reads each threshold as one recall step too low (module docstring)
    assert exact >= validation_ap(model, frames)
    no_doors = [f.select(["window"]) for f in frames]
    with pytest.raises(ValueError, match="no \\['door'\\] boxes"):
        validation_ap(model, no_doors)


def test_encoder_transfer_is_the_only_difference_between_conditions(tmp_path, monkeypatch):
    """Same seed with and without ``init_encoder_from``: the same head initialisation, the same
    frame order and augmentation draws; only the encoder's weights differ."""
    import sim2radar.detect.batches as tr  # where training batches are augmented

    frames = make_door_frames(5, seed=8, points_per_frame=400)
    cfg = small_config(optimization=dict(batch_size=2, epochs=2))
    pre = train(cfg, out_dir=tmp_path / "pre", frames=frames[::-1], seed=11)
    pre_state = torch.load(pre.checkpoint, weights_only=False)["model"]

    seen: dict[str, list] = {}
    orig = tr.augment_frame

    def spy(frame, *args, **kw):
        out = orig(frame, *args, **kw)
        seen[current].append((frame.frame_id, out[0].tobytes(), out[1].tobytes()))
        return out

    monkeypatch.setattr(tr, "augment_frame", spy)
    # lr = 0: AdamW leaves every weight where it started, so the final checkpoint shows the
    # initialisation (BatchNorm running statistics still move; they are buffers, not compared)
    frozen = cfg.with_updates(optimization=dict(lr=0.0))
    finals = {}
    for current, enc in (("baseline", None), ("transfer", pre.checkpoint)):
        seen[current] = []
        res = train(frozen, out_dir=tmp_path / current, frames=frames, seed=5,
                    init_encoder_from=enc)
        finals[current] = torch.load(res.checkpoint, weights_only=False)["model"]
    assert len(seen["baseline"]) == 2 * len(frames)
    assert seen["transfer"] == seen["baseline"]  # same order, same augmented points and boxes

    params = {n for n, _ in PointPillars(cfg.model).named_parameters()}
    head = sorted(n for n in params if n.split(".")[0] not in ENCODER_MODULES)
    encoder = sorted(n for n in params if n.split(".")[0] in ENCODER_MODULES)
    assert head and encoder
    for n in head:  # identical fresh head in both conditions
        torch.testing.assert_close(finals["transfer"][n], finals["baseline"][n], rtol=0, atol=0)
    for n in encoder:  # transfer: the pre-trained encoder; baseline: a different (random) one
        torch.testing.assert_close(finals["transfer"][n], pre_state[n], rtol=0, atol=0)
    assert not all(torch.equal(finals["baseline"][n], pre_state[n]) for n in encoder)
    # and the baseline's encoder is the one the seed alone gives
    torch.manual_seed(5)
    fresh = PointPillars(cfg.model).state_dict()
    for n in params:
        torch.testing.assert_close(finals["baseline"][n], fresh[n], rtol=0, atol=0)


def test_a_checkpoint_carrying_code_is_refused_without_running_it(tmp_path):
    """torch.load(weights_only=False) would execute a pickled __reduce__ payload."""
    import torch

    from sim2radar.detect import DetectConfig, PointPillars
    from sim2radar.detect.train import load_checkpoint, load_encoder_from

    marker = tmp_path / "pwned"

    class Payload:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    bad = tmp_path / "evil.pt"
    torch.save({"model": {}, "config": {}, "x": Payload()}, bad)
    for load in (lambda: load_checkpoint(bad),
                 lambda: load_encoder_from(PointPillars(DetectConfig().model), bad)):
        with pytest.raises(ValueError, match="refused to load"):
            load()
    assert not marker.exists()
    # --resume reads out_dir/last.pt
    root, run = tmp_path / "data", tmp_path / "run"
    write_synthetic_dataset(root, n_train=2, n_val=1, n_test=1, seed=5, points_per_frame=300)
    run.mkdir()
    (run / "last.pt").write_bytes(bad.read_bytes())
    cfg = small_config(data=dict(root=root), optimization=dict(batch_size=2, epochs=1))
    with pytest.raises(ValueError, match="refused to load"):
        train(cfg, out_dir=run, resume=True)
    assert not marker.exists()
    # refused, not healed: it stays where it is for the user to look at
    assert (run / "last.pt").exists() and not (run / "quarantine").exists()


def test_a_failed_run_leaves_no_empty_run_folder(tmp_path):
    """A run that fails before its first checkpoint removes the folders it created; a folder
    that existed before, or that holds a checkpoint to resume from, stays."""
    root = tmp_path / "data"
    write_synthetic_dataset(root, n_train=2, n_val=1, n_test=1, seed=5, points_per_frame=300)
    (root / "labels" / "000000.txt").write_text("1 2 3 door\n")  # a malformed label line
    cfg = small_config(data=dict(root=root), optimization=dict(batch_size=2, epochs=2))
    with pytest.raises(ValueError, match=r"000000.txt:1: expected 8 fields"):
        train(cfg, out_dir=tmp_path / "runs" / "new")
    assert not (tmp_path / "runs").exists()  # the run folder and its parent were new
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    with pytest.raises(ValueError):
        train(cfg, out_dir=tmp_path / "mine")
    assert (tmp_path / "mine" / "notes.txt").is_file()
    # a failure after epoch 1's checkpoint keeps the run, resumable
    frames = make_door_frames(2, seed=6, points_per_frame=300)

    def fail_in_epoch_2(epoch, model):
        if epoch == 2:
            raise RuntimeError("interrupted")

    with pytest.raises(RuntimeError, match="interrupted"):
        train(cfg, out_dir=tmp_path / "late", frames=frames, on_epoch_end=fail_in_epoch_2)
    assert (tmp_path / "late" / "last.pt").is_file()


def test_the_batchnorm_warning_is_said_once_per_process(tmp_path, caplog):
    """Issue #34: a sweep printed the same BatchNorm warning once per run (8 times in the
    smoke profile); now once per process and setting."""
    import logging

    from sim2radar.detect import train as train_mod

    root = tmp_path / "data"
    write_synthetic_dataset(root, n_train=2, n_val=1, n_test=1, seed=5, points_per_frame=300)
    cfg = small_config(data=dict(root=root), optimization=dict(batch_size=2, epochs=1))
    logger = logging.getLogger("sim2radar.detect.train")
    logger.addHandler(caplog.handler)
    train_mod._SAID.clear()
    try:
        for i in range(3):
            train(cfg, out_dir=tmp_path / f"run{i}")
    finally:
        logger.removeHandler(caplog.handler)
    said = {id(r) for r in caplog.records if "will not settle" in r.getMessage()}
    assert len(said) == 1       # (caplog may see a record twice: through root and our handler)


def test_the_initial_weights_come_from_the_seed_alone(tmp_path):
    """seeded_model gives the weights torch.manual_seed(seed) + PointPillars(cfg) gives, while
    another thread keeps saving, drawing from and restoring torch's global generator (what a
    concurrent run's epoch hook and batch loader do) and rebuilding a finished run's model from
    its checkpoint; the global generator is not advanced."""
    import hashlib
    import threading

    from sim2radar.detect.model import seeded_model

    cfg = small_config().model
    done = train(small_config(), out_dir=tmp_path / "done",
                 frames=make_door_frames(2, seed=1, points_per_frame=300), epochs=1, seed=2)

    def digest(model):
        h = hashlib.sha256()
        for v in model.state_dict().values():
            h.update(v.numpy().tobytes())
        return h.hexdigest()

    torch.manual_seed(11)
    want = digest(PointPillars(cfg))
    state = torch.get_rng_state()
    assert digest(seeded_model(cfg, 11)) == want
    assert torch.equal(torch.get_rng_state(), state)
    stop = threading.Event()

    def busy():
        while not stop.is_set():
            with torch.random.fork_rng(devices=[]):
                torch.rand(8)
            load_checkpoint(done.checkpoint)
    other = threading.Thread(target=busy)
    other.start()
    try:
        got = [digest(seeded_model(cfg, 11)) for _ in range(10)]
    finally:
        stop.set()
        other.join()
    assert got == [want] * 10


def test_runs_in_threads_train_as_they_would_alone(tmp_path):
    """Two runs at once in threads of one process (the sweep's thread runner, 2 runs at a time
    in the demo): each ends with the weights it ends with alone, while the other's epoch hook
    and batch loader touch torch's global generator at every epoch."""
    import threading

    frames = make_door_frames(2, seed=1, points_per_frame=300)
    cfg = small_config(optimization=dict(batch_size=2, epochs=1))

    def weights(res):
        return torch.load(res.checkpoint, weights_only=False)["model"]

    def hook(epoch, model):
        return {"x": 1.0}

    settings = {5: dict(epochs=1, on_epoch_end=None), 6: dict(epochs=30, on_epoch_end=hook)}
    alone = [weights(train(cfg, out_dir=tmp_path / f"alone{s}", frames=frames, seed=s, **kw))
             for s, kw in settings.items()]
    got: dict = {}

    def run(seed, n):
        for i in range(n):
            res = train(cfg, out_dir=tmp_path / f"t{seed}_{i}", frames=frames, seed=seed,
                        **settings[seed])
            got.setdefault(seed, []).append(weights(res))

    a = threading.Thread(target=run, args=(6, 1))
    a.start()
    run(5, 10)
    a.join()
    for seed, want in zip((5, 6), alone, strict=True):
        for w in got[seed]:
            for k, v in want.items():
                torch.testing.assert_close(w[k], v, rtol=0, atol=0)
