"""One training run of the sweep, as plain functions: pre-train an encoder, or fine-tune (from
scratch or from a pre-trained encoder) and test.

Both resume: the run folder keeps ``last.pt`` (written at most every ``runtime.last_every_s``,
at every epoch checkpoint and at the end; :func:`sim2radar.detect.train.train` with
``resume=True``), so a run killed half-way continues from its last checkpoint, and a run
whose training finished but whose test was not recorded only re-tests. A finished pre-training
leaves ``done.json`` beside its checkpoint.

The two conditions of a cell call :func:`finetune_and_test` with the same frames, seed, epochs
and config; only ``encoder_checkpoint`` differs (None for the baseline), so the only difference
is the encoder's initialisation (:func:`sim2radar.detect.train.train` seeds the weights before
loading the encoder; the head, shuffling and augmentation follow the seed).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sim2radar.experiment.folder import SweepFolder
from sim2radar.fileio import write_json

__all__ = [
    "NonFiniteLoss",
    "pretrain_encoder",
    "finetune_and_test",
    "test_ap",
    "AP_COLUMNS",
]

#: experiment_runs AP columns -> the keys of :func:`sim2radar.evaluate.evaluate_detections`.
AP_COLUMNS: dict[str, str] = {
    f"ap_{metric}_r{points}_iou{iou.replace('.', '')}": f"{metric}_r{points}@{iou}"
    for iou in ("0.3", "0.5") for metric in ("3d", "bev") for points in (11, 40)
}


class NonFiniteLoss(FloatingPointError):
    """Training diverged (NaN or inf loss); the run is recorded as failed with this message."""


def _check_finite(history: Sequence[dict], what: str) -> None:
    for rec in history:
        loss = rec.get("total")
        if loss is not None and not math.isfinite(float(loss)):
            raise NonFiniteLoss(f"{what}: training loss became {loss} at epoch {rec['epoch']}")


def pretrain_encoder(cfg, frames: Sequence, out_dir: str | Path, *, seed: int, epochs: int,
                     device=None) -> Path:
    """Pre-train on (simulated) ``frames``; returns the checkpoint whose encoder the
    fine-tuning runs load. Skips training when ``out_dir/done.json`` says it finished and its
    ``last.pt`` loads (one that does not is quarantined and the training resumes from the
    newest good ``epoch_<n>.pt``, or restarts).

    Raises :class:`NonFiniteLoss` when the loss diverges.
    """
    from sim2radar.detect.train import checkpoint_loads, quarantine_file, train

    out_dir = Path(out_dir)
    done = out_dir / SweepFolder.DONE
    if done.is_file():
        if checkpoint_loads(out_dir / SweepFolder.LAST_CHECKPOINT):
            return out_dir / SweepFolder.LAST_CHECKPOINT
        # finished, but its checkpoint no longer loads (moved into quarantine/): train again,
        # resuming from its newest good epoch checkpoint
        quarantine_file(done, "its pre-training's last.pt does not load")
    res = train(cfg, out_dir=out_dir, frames=frames, seed=seed, epochs=epochs, resume=True,
                device=device)
    _check_finite(res.history, f"pre-training in {out_dir}")
    write_json(done, {"epochs": res.epochs, "steps": res.steps, "frames": len(frames),
                       "seconds": res.seconds, "history": res.history})
    return res.checkpoint


def test_ap(model, frames: Sequence) -> dict[str, float]:
    """Every AP figure of the protocol (:func:`sim2radar.evaluate.evaluate_detections`, KITTI
    devkit thresholds) of ``model`` on ``frames``, keyed by experiment_runs column."""
    from sim2radar.detect.train import predict_frames
    from sim2radar.evaluate import evaluate_detections

    dets = predict_frames(model, frames)
    res = evaluate_detections([f.boxes for f in frames], [d.boxes.numpy() for d in dets],
                              [d.scores.numpy() for d in dets])
    return {col: float(res[key]) for col, key in AP_COLUMNS.items()}


def finetune_and_test(
    cfg,
    train_frames: Sequence,
    test_frames: Sequence,
    out_dir: str | Path,
    *,
    seed: int,
    epochs: int,
    encoder_checkpoint: str | Path | None = None,
    val_frames: Sequence = (),
    val_every: int = 0,
    max_val_points: int | None = None,
    device=None,
) -> dict[str, Any]:
    """Fine-tune on ``train_frames`` (encoder from ``encoder_checkpoint``, or from scratch) and
    test; returns the run's experiment_runs fields (AP columns, ``epochs``, ``steps``,
    ``history_*``, ``wall_time_s``, ``device``).

    ``val_every`` > 0: 3D AP (R40, IoU 0.3) on ``val_frames`` every that many epochs and at the
    last epoch, for the learning curves (it does not select the checkpoint: the last epoch is
    tested, as in the paper). ``max_val_points`` caps their number: the interval becomes
    ``max(val_every, ceil(epochs / max_val_points))`` epochs.
    """
    from sim2radar.detect.train import load_checkpoint, train, validation_ap

    out_dir = Path(out_dir)
    hook = None
    if val_every and len(val_frames):
        every = int(val_every)
        if max_val_points:
            every = max(every, -(-int(epochs) // int(max_val_points)))

        def hook(epoch: int, model) -> dict[str, float] | None:
            if epoch % every == 0 or epoch == int(epochs):
                return {"val_ap": validation_ap(model, list(val_frames))}
            return None

    res = train(cfg, out_dir=out_dir, frames=train_frames, seed=seed, epochs=epochs,
                init_encoder_from=encoder_checkpoint, resume=True, device=device,
                on_epoch_end=hook)
    _check_finite(res.history, f"fine-tuning in {out_dir}")
    t_test = time.perf_counter()
    model, _ = load_checkpoint(res.checkpoint, device)
    row: dict[str, Any] = test_ap(model, test_frames)
    hist = res.history
    # training time from the epochs' own timings (also right for a resumed run), plus the test
    seconds = sum(float(h.get("seconds", 0.0)) for h in hist) + time.perf_counter() - t_test
    row.update(
        epochs=int(res.epochs), steps=int(res.steps),
        history_epoch=[int(h["epoch"]) for h in hist],
        history_loss=[float(h["total"]) for h in hist],
        history_val_epoch=[int(h["epoch"]) for h in hist if "val_ap" in h],
        history_val_ap=[float(h["val_ap"]) for h in hist if "val_ap" in h],
        wall_time_s=seconds,
        device=str(next(model.parameters()).device),
    )
    if not all(np.isfinite(v) for k, v in row.items() if k.startswith("ap_")):
        raise NonFiniteLoss(f"fine-tuning in {out_dir}: AP is not finite")
    return row
