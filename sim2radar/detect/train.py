"""Training, encoder transfer and evaluation of PointPillars as plain functions.

``train``, ``validation_ap`` and ``evaluate_checkpoint`` are what the experiment sweep calls::

    pre = train(cfg, out_dir=pre_dir, frames=sim_frames, seed=s, epochs=20)
    res = train(cfg, out_dir=run_dir, frames=real_subset, seed=s, init_encoder_from=pre.checkpoint,
                on_epoch_end=lambda e, m: {"val_ap": validation_ap(m, val_frames)})
    ap = evaluate_checkpoint(res.checkpoint, split="test")     # {"3d_r11@0.3": ..., ...}

Encoder transfer is the only difference between a run with ``init_encoder_from`` and one without
at the same seed: the head's initial weights, the shuffling and the augmentation draws are the
same (the weights are drawn before the encoder is loaded; the data order does not depend on it).

Optimisation follows OpenPCDet's ``adam_onecycle``: AdamW (betas 0.9/0.99, decoupled weight
decay on every parameter), one-cycle learning rate (cosine warm-up from lr/10 to lr over 40 %
of the steps, cosine decay to lr/1e5) with inverse momentum (beta1 0.95 -> 0.85 -> 0.95),
gradient-norm clipping at 10. Randomness: the seed fixes the initial weights (the weights
``torch.manual_seed(seed)`` gives, drawn from a generator of the run's own,
:func:`~sim2radar.detect.model.seeded_model`, so runs training at once in threads of one
process cannot change each other's); epoch ``e`` draws its frame order from
``numpy.random.default_rng([seed, e])`` and batch ``k``'s augmentation from child ``k`` of
``SeedSequence([seed, e])`` (:mod:`sim2radar.detect.batches`, made in
``runtime.loader_workers`` DataLoader workers), so a resumed run continues exactly as an
uninterrupted one, whatever the worker count. An
``on_epoch_end`` hook (e.g. validation AP) runs with torch's random state saved and restored,
so it cannot change the training either.
"""

from __future__ import annotations

import contextlib
import functools
import json
import logging
import math
import pickle
import shutil
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from sim2radar.datasets.openpcdet import Frame, OpenPCDetDataset
from sim2radar.detect.augment import GTDatabase, build_gt_database
from sim2radar.detect.batches import TrainingBatches, collate, resolve_loader_workers
from sim2radar.detect.config import DetectConfig, load_config
from sim2radar.detect.model import ENCODER_MODULES, Detections, PointPillars, seeded_model
from sim2radar.evaluate.ap import evaluate_detections
from sim2radar.fileio import atomic_write_with
from sim2radar.hardware import autocast_dtype

__all__ = [
    "TrainResult",
    "collate",
    "evaluate_checkpoint",
    "load_checkpoint",
    "load_encoder_from",
    "UnsafeCheckpointError",
    "checkpoint_loads",
    "quarantine_file",
    "predict_frames",
    "train",
    "validation_ap",
]

CHECKPOINT_VERSION = 1
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrainResult:
    """Outcome of :func:`train`.

    Attributes
    ----------
    checkpoint : path of the final checkpoint (``out_dir/last.pt``).
    out_dir : run folder (checkpoints, ``history.json``, ``config.json``).
    epochs : epochs completed; steps : optimiser steps completed.
    history : one dict per epoch: ``epoch`` (1-based), mean ``cls``/``loc``/``dir``/``total``
        loss, ``lr`` (of the epoch's last step), ``seconds`` (the epoch's wall time, hook
        included [s]) and, with an ``on_epoch_end`` hook, ``hook_seconds`` [s] and the fields
        the hook returned (e.g. ``val_ap``).
    seconds : wall time of this call [s].
    """

    checkpoint: Path
    out_dir: Path
    epochs: int
    steps: int
    history: list[dict[str, float]] = field(default_factory=list)
    seconds: float = 0.0


def _autocast(device: torch.device, dtype: torch.dtype | None):
    """Mixed precision in ``dtype`` (:func:`sim2radar.hardware.autocast_dtype`), or none."""
    if dtype is None:
        return contextlib.nullcontext()
    return torch.autocast(device.type, dtype=dtype)


_SAID: set = set()
_SAID_LOCK = threading.Lock()


def _first_time(what) -> bool:
    """True the first time ``what`` is asked about in this process (a warning a sweep would
    otherwise print once per run)."""
    with _SAID_LOCK:
        if what in _SAID:
            return False
        _SAID.add(what)
        return True


def _resolve_device(cfg: DetectConfig, device) -> torch.device:
    from sim2radar.hardware import torch_device

    return torch.device(device) if device is not None else torch_device(cfg.runtime.device)


# ---------------------------------------------------------------------------- checkpoints
def _save(path: Path, payload: dict[str, Any]) -> None:
    atomic_write_with(path, lambda tmp: torch.save(payload, tmp))


def _versions() -> dict[str, str]:
    return dict(_installed_versions())


@functools.cache
def _installed_versions() -> dict[str, str]:
    """The versions a checkpoint records, read once per process (reading package metadata
    took ~2 ms, paid on every checkpoint)."""
    import importlib.metadata as md

    out = {}
    for pkg in ("sim2radar", "torch", "numpy"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = "unknown"
    return out


class UnsafeCheckpointError(ValueError):
    """A checkpoint holding pickled objects other than tensors and plain data: it is refused,
    never healed (quarantining it and training on would hide a tampered run folder)."""


def _read_checkpoint(path: str | Path, map_location="cpu") -> dict[str, Any]:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint {path} does not exist")
    try:
        # tensors and plain data only: a pickled object could run code when loaded
        ckpt = torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as exc:
        if "global" not in str(exc).lower():  # garbage bytes ("Unsupported operand", "load key")
            lines = [ln for ln in str(exc).splitlines() if ln.strip()] or [type(exc).__name__]
            why = next((ln for ln in lines if "Unsupported" in ln or "load key" in ln), lines[0])
            raise ValueError(f"{path}: not a readable checkpoint (damaged or not a torch file): "
                             f"{why.strip()}") from None
        raise UnsafeCheckpointError(f"{path}: refused to load: the file holds objects other than tensors "
                         "and plain data (a sim2radar checkpoint never does; it may be "
                         f"malicious): {str(exc).splitlines()[0]}") from None
    if not isinstance(ckpt, dict) or "model" not in ckpt:
        raise ValueError(f"{path}: not a sim2radar PointPillars checkpoint (no 'model' entry)")
    return ckpt


def quarantine_file(path: Path, why: str) -> Path:
    """Move a file that cannot be used into ``<its folder>/quarantine/`` (timestamped; nothing
    is deleted), with one warning naming it and why; returns where it went."""
    stamp = time.strftime("%Y%m%dT%H%M%S", time.gmtime())
    dest = path.parent / "quarantine" / f"{path.name}.{stamp}"
    dest.parent.mkdir(parents=True, exist_ok=True)
    path.replace(dest)
    log.warning("%s: %s; moved to %s", path, why, dest)
    return dest


def _loads(path: Path, map_location) -> dict[str, Any] | None:
    """The checkpoint at ``path``, or None after quarantining it when it does not load
    (truncated, not a zip, not a sim2radar checkpoint). One carrying code is not damage: it
    raises :class:`UnsafeCheckpointError` and stays where it is for the user to look at."""
    try:
        return _read_checkpoint(path, map_location=map_location)
    except UnsafeCheckpointError:
        raise
    except FileNotFoundError:
        return None
    except Exception as exc:  # noqa: BLE001 - torch raises RuntimeError/EOFError/zip errors
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        quarantine_file(path, f"checkpoint does not load ({type(exc).__name__}: {first})")
        return None


def _resume_checkpoint(out_dir: Path, map_location) -> dict[str, Any] | None:
    """The checkpoint a run resumes from: ``last.pt``, or — when it does not load (a killed
    write, a truncated copy) — the newest ``epoch_<n>.pt`` that does, each unloadable one moved
    into ``quarantine/`` with a warning; None: start from scratch."""
    candidates = [out_dir / "last.pt"] + sorted(
        out_dir.glob("epoch_*.pt"), key=lambda p: -int(p.stem.split("_")[1]))
    for i, path in enumerate(candidates):
        ckpt = _loads(path, map_location)
        if ckpt is not None:
            if i:
                log.warning("%s: resuming from %s (epoch %s)", out_dir, path.name,
                            ckpt.get("epoch"))
            return ckpt
    return None


def checkpoint_loads(path: str | Path) -> bool:
    """Whether ``path`` loads as a sim2radar checkpoint; one that does not is moved into
    ``quarantine/`` beside it (a finished pre-training whose ``last.pt`` was truncated heals:
    its caller trains it again, resuming from its newest good ``epoch_<n>.pt``)."""
    return _loads(Path(path), "cpu") is not None


def load_checkpoint(path: str | Path, device=None) -> tuple[PointPillars, DetectConfig]:
    """Rebuild the model of a checkpoint (eval mode) and its config."""
    ckpt = _read_checkpoint(path)
    cfg = DetectConfig.model_validate(ckpt["config"])
    # built like a training run's model (one build at a time, its own generator: a run
    # building in another thread meanwhile keeps its seed's weights); the checkpoint's
    # weights then replace the initial ones
    model = seeded_model(cfg.model, cfg.seed)
    model.load_state_dict(ckpt["model"])
    dev = torch.device(device) if device is not None else _resolve_device(cfg, None)
    return model.to(dev).eval(), cfg


def load_encoder_from(model: PointPillars, path: str | Path) -> list[str]:
    """Initialise ``model``'s encoder (VFE + scatter + backbone) from a checkpoint.

    The head keeps its fresh initialisation. Returns the loaded parameter names.
    """
    ckpt = _read_checkpoint(path)
    try:
        return model.load_encoder(ckpt["model"])
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from exc


# ---------------------------------------------------------------------------- data
def _load_frames(cfg: DetectConfig, data_dir, split: str, ids: Sequence[str] | None):
    root = Path(data_dir) if data_dir is not None else cfg.data.root
    if root is None:
        raise ValueError("no dataset: set data.root in the config or pass data_dir")
    ds = OpenPCDetDataset(root, num_point_features=cfg.model.num_point_features,
                          drop_extra_columns=cfg.data.drop_extra_point_columns)
    ids = list(ids) if ids is not None else ds.split_ids(split)
    if not ids:
        raise ValueError(f"{root}: no frames selected (split {split!r} is empty)")
    frames = [f.select(cfg.model.class_names) for f in ds.frames(ids)]
    return root, frames


# ---------------------------------------------------------------------------- training
#: ``on_epoch_end(epoch, model)``: epoch is 1-based; the returned fields join the epoch's record
EpochHook = Callable[[int, PointPillars], Mapping[str, Any] | None]
_RESERVED = frozenset({"epoch", "lr", "seconds", "hook_seconds", "cls", "loc", "dir", "total"})


def _run_hook(hook: EpochHook, epoch: int, model: PointPillars,
              dev: torch.device) -> dict[str, Any]:
    """Call the hook with torch's random state saved and restored, then put the model back in
    train mode; check that what it returned can join a JSON history record."""
    devices = [dev.index if dev.index is not None else torch.cuda.current_device()] \
        if dev.type == "cuda" else []
    with torch.random.fork_rng(devices=devices):
        extra = hook(epoch, model)
    model.train()
    if extra is None:
        return {}
    if not isinstance(extra, Mapping):
        raise TypeError(f"on_epoch_end must return a dict or None, got {type(extra).__name__}")
    out: dict[str, Any] = {}
    for key, value in extra.items():
        if not isinstance(key, str) or key in _RESERVED:
            raise ValueError(f"on_epoch_end returned field {key!r}: fields must be strings "
                             f"other than {sorted(_RESERVED)}")
        if isinstance(value, (bool, str)) or value is None:
            out[key] = value
        elif isinstance(value, (int, float, np.integer, np.floating)):
            out[key] = float(value)
        else:
            raise TypeError(f"on_epoch_end field {key!r}: expected a number, string, bool or "
                            f"None, got {type(value).__name__}")
    return out


def train(
    config: DetectConfig | str | Path,
    train_ids: Sequence[str] | None = None,
    out_dir: str | Path = "runs/pointpillars",
    init_encoder_from: str | Path | None = None,
    seed: int | None = None,
    *,
    data_dir: str | Path | None = None,
    epochs: int | None = None,
    resume: bool = False,
    device: str | torch.device | None = None,
    frames: Sequence[Frame] | None = None,
    on_epoch_end: EpochHook | None = None,
) -> TrainResult:
    """Train PointPillars from a config.

    Parameters
    ----------
    config : :class:`DetectConfig` or a YAML path.
    train_ids : frame ids to train on (default: the config's train split). The GT-sampling
        database is built from these frames only.
    out_dir : run folder; ``last.pt`` and ``epoch_<n>.pt`` checkpoints go here.
    init_encoder_from : checkpoint whose encoder initialises the model (overrides
        ``config.pretrained_encoder``); the head starts fresh.
    seed : overrides ``config.seed``.
    data_dir : overrides ``config.data.root``.
    epochs : overrides ``config.optimization.epochs``.
    resume : continue from ``out_dir/last.pt`` if it exists (same config required).
    device : overrides ``config.runtime.device``.
    frames : train on these in-memory frames instead of reading the dataset.
    on_epoch_end : ``hook(epoch, model) -> dict | None``, called after every epoch (1-based
        ``epoch``) before its checkpoint is written. The dict's fields (numbers, strings) join
        that epoch's history record, so they are saved in the checkpoints and survive
        ``resume=True`` (a resumed run calls the hook only for the epochs it trains). The hook
        may leave the model in eval mode; training continues in train mode, with torch's random
        state as it was before the hook.

    Returns
    -------
    TrainResult

    A run that fails before its first checkpoint removes the run folder (and the parents) it
    created, so a bad dataset or config leaves no empty run behind; a folder that existed
    before, or holds a checkpoint to resume from, is kept.
    """
    out_dir = Path(out_dir)
    with _run_folder(out_dir):
        return _train(config, train_ids, out_dir, init_encoder_from, seed, data_dir=data_dir,
                      epochs=epochs, resume=resume, device=device, frames=frames,
                      on_epoch_end=on_epoch_end)


@contextlib.contextmanager
def _run_folder(out_dir: Path):
    """Create ``out_dir`` (and missing parents) for a run; if the run raises before writing a
    checkpoint, remove what it created: its ``config.json`` and the folders, innermost first,
    each only if then empty."""
    created = [p for p in (out_dir, *out_dir.parents) if not p.exists()]
    out_dir.mkdir(parents=True, exist_ok=True)
    try:
        yield
    except BaseException:
        if created and not any(out_dir.glob("*.pt")):
            (out_dir / "config.json").unlink(missing_ok=True)
            for folder in created:
                try:
                    folder.rmdir()
                except OSError:  # not empty: someone else's files are in there
                    break
        raise


def _param_groups(model: PointPillars, lr: float, encoder_scale: float) -> list[dict]:
    """AdamW parameter groups: everything at ``lr``, or (``encoder_scale`` < 1) the encoder's
    parameters (:data:`~sim2radar.detect.model.ENCODER_MODULES`) at ``lr * encoder_scale`` in
    a first group and the rest at ``lr``; the one-cycle schedule scales each group's peak."""
    if encoder_scale == 1.0:
        return [{"params": list(model.parameters()), "lr": lr}]
    enc, rest = [], []
    for name, p in model.named_parameters():
        (enc if name.split(".", 1)[0] in ENCODER_MODULES else rest).append(p)
    return [{"params": enc, "lr": lr * encoder_scale}, {"params": rest, "lr": lr}]


def _train_epoch(epoch: int, batches: TrainingBatches, model: PointPillars, optimizer,
                 scheduler, scaler, amp_dtype, dev: torch.device, grad_norm_clip: float,
                 progress, on_epoch_end: EpochHook | None) -> dict[str, Any]:
    """One epoch (0-based ``epoch``) of optimiser steps; its history record."""
    t_epoch = time.perf_counter()
    sums: dict[str, float] = {}
    for pts, gt, n_frames in batches.epoch(epoch):
        with _autocast(dev, amp_dtype):
            out = model(pts, n_frames)
        loss, parts = model.loss(out, gt)
        optimizer.zero_grad(set_to_none=True)
        scaler.scale(loss).backward()
        scaler.unscale_(optimizer)
        torch.nn.utils.clip_grad_norm_(model.parameters(), grad_norm_clip)
        lr_used = optimizer.param_groups[-1]["lr"]      # the head's (the peak lr)
        scaler.step(optimizer)
        scaler.update()
        scheduler.step()
        for k, v in parts.items():
            sums[k] = sums.get(k, 0.0) + v
        if progress is not None:
            progress.update(1)
            progress.set_postfix(epoch=epoch + 1, loss=f"{parts['total']:.3f}")
    record: dict[str, Any] = {k: v / len(batches) for k, v in sums.items()}
    record.update(epoch=epoch + 1, lr=lr_used)
    if on_epoch_end is not None:
        t_hook = time.perf_counter()
        record.update(_run_hook(on_epoch_end, epoch + 1, model, dev))
        record["hook_seconds"] = time.perf_counter() - t_hook
    record["seconds"] = time.perf_counter() - t_epoch
    return record


def _train(config, train_ids, out_dir: Path, init_encoder_from, seed, *, data_dir, epochs,
           resume, device, frames, on_epoch_end) -> TrainResult:
    """:func:`train` inside its run folder."""
    t_start = time.perf_counter()
    cfg = load_config(config) if isinstance(config, (str, Path)) else config
    if seed is not None:
        cfg = cfg.model_copy(update={"seed": int(seed)})
    if epochs is not None:
        cfg = cfg.with_updates(optimization={"epochs": int(epochs)})
    encoder_ckpt = init_encoder_from if init_encoder_from is not None else cfg.pretrained_encoder
    dev = _resolve_device(cfg, device)
    rt, opt_cfg, mcfg = cfg.runtime, cfg.optimization, cfg.model
    if rt.num_threads and dev.type == "cpu":
        torch.set_num_threads(rt.num_threads)

    if frames is None:
        _, frames = _load_frames(cfg, data_dir, cfg.data.train_split, train_ids)
    else:
        frames = [f.select(mcfg.class_names) for f in frames]
        for f in frames:
            if f.points.shape[1] != mcfg.num_point_features:
                raise ValueError(
                    f"frame {f.frame_id}: points have {f.points.shape[1]} columns but "
                    f"model.num_point_features={mcfg.num_point_features}"
                )
    db: GTDatabase | None = None
    if cfg.augmentation.gt_sampling:
        db = build_gt_database(frames, mcfg.class_names, cfg.augmentation.min_points_in_gt)

    model = seeded_model(mcfg, cfg.seed)  # torch's global generator is not involved
    loaded_encoder: list[str] = []
    if encoder_ckpt is not None:
        loaded_encoder = load_encoder_from(model, encoder_ckpt)
    model.to(dev)
    # foreach: the multi-tensor update on every device (torch's default only on CUDA): on a CPU
    # it is the same arithmetic, bit for bit, without a Python loop over the ~30 parameters
    optimizer = torch.optim.AdamW(_param_groups(model, opt_cfg.lr, opt_cfg.encoder_lr_scale),
                                  lr=opt_cfg.lr, betas=opt_cfg.betas,
                                  weight_decay=opt_cfg.weight_decay, foreach=True)
    bs = opt_cfg.batch_size
    steps_per_epoch = math.ceil(len(frames) / bs)
    total_steps = steps_per_epoch * opt_cfg.epochs
    scheduler = torch.optim.lr_scheduler.OneCycleLR(
        optimizer, max_lr=[g["lr"] for g in optimizer.param_groups], total_steps=total_steps, pct_start=opt_cfg.pct_start,
        anneal_strategy="cos", cycle_momentum=True, base_momentum=opt_cfg.moms[1],
        max_momentum=opt_cfg.moms[0], div_factor=opt_cfg.div_factor,
        final_div_factor=opt_cfg.final_div_factor,
    )
    if (1 - mcfg.bn_momentum) ** total_steps > 0.05 and \
            _first_time(("bn", total_steps, mcfg.bn_momentum)):  # once per process (a sweep)
        log.warning(
            "BatchNorm running statistics will not settle in %d steps with model.bn_momentum="
            "%g (eval-mode scores will be too low); use more epochs or bn_momentum >= %.2f",
            total_steps, mcfg.bn_momentum, min(1.0, 3.0 / total_steps),
        )
    amp_dtype = autocast_dtype(dev, rt.amp)
    # float16 needs loss scaling against gradient underflow; bfloat16 has float32's range
    scaler = torch.amp.GradScaler("cuda", enabled=amp_dtype == torch.float16)

    start_epoch, history = 0, []
    last = out_dir / "last.pt"
    ckpt = _resume_checkpoint(out_dir, dev) if resume else None
    if ckpt is not None:
        saved = DetectConfig.model_validate(ckpt["config"])
        for section in ("model", "optimization", "augmentation"):
            if getattr(saved, section) != getattr(cfg, section):
                raise ValueError(f"{last}: cannot resume, config section {section!r} differs "
                                 "from the checkpoint's; use a new out_dir")
        if ckpt.get("train_ids") != [f.frame_id for f in frames] or ckpt["seed"] != cfg.seed:
            raise ValueError(f"{last}: cannot resume with different train frames or seed")
        if "random_draws" not in dict(ckpt["config"].get("augmentation") or {}):
            raise ValueError(f"{last}: cannot resume a run trained before issue #31 (one random "
                             "stream per epoch; batches now draw per batch, "
                             "sim2radar.detect.batches); use a new out_dir")
        model.load_state_dict(ckpt["model"])
        optimizer.load_state_dict(ckpt["optimizer"])
        scheduler.load_state_dict(ckpt["scheduler"])
        start_epoch, history = int(ckpt["epoch"]), list(ckpt["history"])

    if rt.compile:
        model.compile_dense()
    (out_dir / "config.json").write_text(json.dumps(cfg.model_dump(mode="json"), indent=1))

    last_written = time.monotonic()

    def checkpoint(epoch: int, *, force: bool = False) -> Path:
        """Write ``last.pt`` after ``epoch`` when it is due (``runtime.last_every_s``), after
        the first epoch this call trains (a disk that cannot take it fails at once), at an
        epoch checkpoint, at the final epoch or when ``force``d; an epoch checkpoint is a copy
        of it."""
        nonlocal last_written
        keep = epoch % rt.checkpoint_every == 0 or epoch == opt_cfg.epochs
        due = time.monotonic() - last_written >= rt.last_every_s
        if not (force or keep or due or epoch == start_epoch + 1):
            return last
        payload = {
            "version": CHECKPOINT_VERSION, "model": model.state_dict(),
            "optimizer": optimizer.state_dict(), "scheduler": scheduler.state_dict(),
            "epoch": epoch, "seed": cfg.seed, "history": history,
            "config": cfg.model_dump(mode="json"), "train_ids": [f.frame_id for f in frames],
            "encoder_from": str(encoder_ckpt) if encoder_ckpt else None,
            "versions": _versions(),
        }
        _save(last, payload)
        last_written = time.monotonic()
        if keep:
            atomic_write_with(out_dir / f"epoch_{epoch}.pt",
                              lambda tmp: shutil.copyfile(last, tmp))
            old = sorted(out_dir.glob("epoch_*.pt"), key=lambda p: int(p.stem.split("_")[1]))
            for p in old[: max(0, len(old) - rt.keep_checkpoints)]:
                p.unlink()
        return last

    progress = None
    if rt.progress:
        from tqdm.auto import tqdm

        progress = tqdm(total=total_steps, initial=start_epoch * steps_per_epoch,
                        desc=f"train {cfg.name}", unit="step", dynamic_ncols=True)
    model.train()
    batches = TrainingBatches(frames, bs, cfg.augmentation, mcfg, db, cfg.seed, dev,
                              workers=resolve_loader_workers(rt.loader_workers, dev),
                              prefetch_factor=rt.loader_prefetch, epochs=opt_cfg.epochs)
    with batches:
        for epoch in range(start_epoch, opt_cfg.epochs):
            history.append(_train_epoch(epoch, batches, model, optimizer, scheduler, scaler,
                                        amp_dtype, dev, opt_cfg.grad_norm_clip, progress,
                                        on_epoch_end))
            checkpoint(epoch + 1)
    if progress is not None:
        progress.close()
    if not last.is_file():  # zero epochs left to run: still leave a checkpoint
        checkpoint(start_epoch, force=True)
    (out_dir / "history.json").write_text(json.dumps(
        {"history": history, "encoder_loaded": loaded_encoder}, indent=1))
    return TrainResult(checkpoint=last, out_dir=out_dir, epochs=opt_cfg.epochs,
                       steps=opt_cfg.epochs * steps_per_epoch, history=history,
                       seconds=time.perf_counter() - t_start)


# ---------------------------------------------------------------------------- inference
@torch.no_grad()
def predict_frames(
    model: PointPillars, frames: Sequence[Frame], batch_size: int = 8
) -> list[Detections]:
    """Run the model (eval mode) on frames; returns CPU :class:`Detections` per frame."""
    model.eval()
    dev = next(model.parameters()).device
    out: list[Detections] = []
    for i in range(0, len(frames), batch_size):
        chunk = frames[i : i + batch_size]
        pts, _ = collate([f.points for f in chunk], [np.zeros((0, 7))] * len(chunk),
                         [()] * len(chunk), model.cfg.class_names, dev)
        for d in model.predict(model(pts, len(chunk))):
            out.append(Detections(d.boxes.cpu(), d.scores.cpu(), d.labels.cpu()))
    return out


def validation_ap(
    model: PointPillars,
    frames: Sequence[Frame],
    iou: float = 0.3,
    recall_points: int = 40,
    *,
    thresholds: str = "devkit",
    batch_size: int = 8,
) -> float:
    """3D AP [%] of ``model`` on ``frames`` (the learning-curve figure of a sweep).

    :func:`predict_frames` + :func:`sim2radar.evaluate.evaluate_detections` at one IoU and one
    recall-point set; boxes of classes the model does not detect are ignored. The model's
    train/eval mode is restored afterwards, so this can run inside ``train``'s
    ``on_epoch_end`` hook.

    Parameters
    ----------
    model : the detector (any mode; evaluated in eval mode, without gradients).
    frames : frames with ground-truth boxes (at least one box of the model's classes).
    iou : IoU threshold (strict) for a true positive; 0.3 is the paper's.
    recall_points : 11 or 40.
    thresholds : ``"devkit"`` or ``"all"`` (:mod:`sim2radar.evaluate.ap`; the devkit's AP is
        biased low on sets with fewer than 41 boxes).
    batch_size : frames per forward pass.

    Returns
    -------
    float — AP [%] in [0, 100].
    """
    frames = [f.select(model.cfg.class_names) for f in frames]
    if not any(len(f.boxes) for f in frames):
        raise ValueError(f"validation_ap: the {len(frames)} frames have no "
                         f"{list(model.cfg.class_names)} boxes; AP is undefined")
    was_training = model.training
    try:
        dets = predict_frames(model, frames, batch_size)
    finally:
        model.train(was_training)
    res = evaluate_detections(
        [f.boxes for f in frames], [d.boxes.numpy() for d in dets],
        [d.scores.numpy() for d in dets], iou_thresholds=(float(iou),), metrics=("3d",),
        recall_points=(int(recall_points),), thresholds=thresholds,
    )
    return float(res[f"3d_r{int(recall_points)}@{float(iou):g}"])


def evaluate_checkpoint(
    checkpoint: str | Path,
    data_dir: str | Path | None = None,
    split: str = "test",
    ids: Sequence[str] | None = None,
    *,
    device: str | torch.device | None = None,
    batch_size: int = 8,
    iou_thresholds: Sequence[float] = (0.3, 0.5),
    thresholds: str = "devkit",
) -> dict[str, float]:
    """KITTI-protocol AP of a checkpoint on a split (``thresholds``: ``"devkit"`` or ``"all"``,
    see :mod:`sim2radar.evaluate.ap`).

    Returns
    -------
    dict — ``"3d_r11@0.3"``, ``"3d_r40@0.3"``, ``"bev_r11@0.3"``, ... AP [%] (see
    :func:`sim2radar.evaluate.evaluate_detections`), plus ``frames``, ``gt_boxes``,
    ``detections`` (counts) and ``seconds`` (inference + evaluation wall time [s]).
    """
    t0 = time.perf_counter()
    model, cfg = load_checkpoint(checkpoint, device)
    _, frames = _load_frames(cfg, data_dir, split, ids)
    dets = predict_frames(model, frames, batch_size)
    res = evaluate_detections(
        [f.boxes for f in frames], [d.boxes.numpy() for d in dets],
        [d.scores.numpy() for d in dets], iou_thresholds=iou_thresholds, thresholds=thresholds,
    )
    res.update(frames=float(len(frames)), gt_boxes=float(sum(len(f.boxes) for f in frames)),
               detections=float(sum(len(d.scores) for d in dets)),
               seconds=time.perf_counter() - t0)
    return res
