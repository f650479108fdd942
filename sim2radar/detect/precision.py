"""Training precision chosen by measurement: ``runtime.amp: auto`` decided from a short timed
probe of the model itself on the device it will train on, recorded so every later decision
for that device and model reuses it.

    decision = decide_precision(cfg, "cuda", table=Path("out/sweeps/.precision"))
    decision.amp                 # True: train with autocast (bfloat16 / float16), False: float32
    decision.seconds_per_step    # {"float32": 0.041, "bfloat16": 0.046}: what the probe measured

Why measure: mixed precision is not faster everywhere. On one H100 the paper model's step was
0.041 s in float32 and 0.046 s with bfloat16 autocast (small convolutions, the step bound by
the host); on a CPU without native bfloat16, oneDNN emulates it and it is slower still.

The rule (fixed before any probe ran): mixed precision is chosen only when its median step is
at least :data:`MIN_GAIN` (5 %) faster than float32's; otherwise float32, the numerically
safer default. CPUs without native bfloat16 are decided by the table without a probe
(float32). A decision is stored per device and model in ``table`` (one JSON file each, named
by the device and a digest of the model, batch and augmentation), so a timing-noise flip can
never change the precision — and with it the run keys — of two sweeps on the same machine.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import statistics
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["MIN_GAIN", "PROBE_STEPS", "PrecisionDecision", "decide_precision", "device_name",
           "measure_step_seconds", "prefers_mixed", "probe_step_seconds"]

#: mixed precision must beat float32's median step by this fraction to be chosen
MIN_GAIN = 0.05
#: timed steps per precision in a probe (after one warm-up step)
PROBE_STEPS = 4
#: points per synthetic frame of the probe (IFR's density)
_PROBE_POINTS = 2000


@dataclasses.dataclass(frozen=True)
class PrecisionDecision:
    """What ``amp: auto`` became, and why.

    Attributes
    ----------
    amp : bool — train with autocast (the mixed dtype below) or in float32.
    dtype : str — ``float32``, ``bfloat16`` or ``float16``.
    device : str — the device it was decided for (:func:`device_name`).
    source : str — ``probe`` (measured now), ``recorded`` (an earlier probe's file),
        ``table`` (no probe needed: a CPU without native bfloat16), ``fixed`` (the config said
        true/false), ``rule`` (not probed: a cost estimate only).
    seconds_per_step : dict — dtype -> median seconds per training step the probe measured.
    steps : int — timed steps per dtype.
    reason : str — one sentence.
    """

    amp: bool
    dtype: str
    device: str
    source: str
    seconds_per_step: dict[str, float] = dataclasses.field(default_factory=dict)
    steps: int = 0
    reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def device_name(device, threads: int | None = None) -> str:
    """A stable name of ``device``'s hardware: the GPU's name for CUDA; for a CPU its model and
    the threads a run trains with — ``threads`` (a config's ``runtime.num_threads``), else the
    cores this process may use. Not torch's current thread count: a training run sets it
    (``runtime.num_threads``) and does not restore it, so the same sweep prepared again in
    one process would name another device and decide its precision anew."""
    import torch

    device = torch.device(device)
    if device.type == "cuda":
        return f"cuda:{torch.cuda.get_device_name(device)}"
    model = ""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            model = next((ln.split(":", 1)[1].strip() for ln in fh
                          if ln.startswith("model name")), "")
    except OSError:
        pass
    n = int(threads) if threads else len(os.sched_getaffinity(0))
    return f"cpu:{model or os.uname().machine}:{n} threads"


def _mixed_dtype(device) -> Any:
    """The autocast dtype mixed precision would use on ``device``."""
    from sim2radar.hardware import autocast_dtype

    return autocast_dtype(device, True)


def _digest(cfg) -> str:
    """What a stored decision is keyed by: the workload (model, augmentation, batch). The
    order of random draws (``augmentation.random_draws``) costs nothing and is left out, so
    the decisions measured before it existed still apply."""
    aug = cfg.augmentation.model_dump(mode="json", exclude={"random_draws"})
    doc = {"model": cfg.model.model_dump(mode="json"), "augmentation": aug,
           "batch_size": cfg.optimization.batch_size}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:16]


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-." else "_" for c in text)[:80]


def measure_step_seconds(cfg, frames: Sequence[Any], *, steps_per_epoch: int = 3,
                         epochs: int = 3, device=None) -> float:
    """Median seconds per optimiser step of ``cfg`` (a resolved DetectConfig: model, batch,
    precision, threads) on this machine, training on the first ``steps_per_epoch x batch``
    of ``frames`` for ``epochs`` epochs and timing the epochs after the first (warm-up)."""
    from sim2radar.detect.train import train

    if epochs < 2:
        raise ValueError("epochs must be >= 2: the first epoch is warm-up")
    batch = int(cfg.optimization.batch_size)
    subset = list(frames)[: max(1, steps_per_epoch * batch)]
    if not subset:
        raise ValueError("no frames to time a training step on")
    train_log = logging.getLogger("sim2radar.detect.train")
    level = train_log.level
    train_log.setLevel(logging.ERROR)     # a few steps: BatchNorm's "will not settle" is moot
    try:
        with tempfile.TemporaryDirectory(prefix="sim2radar-step-") as tmp:
            res = train(cfg.with_updates(runtime={"progress": False}), out_dir=tmp,
                        frames=subset, epochs=epochs, seed=0, device=device)
    finally:
        train_log.setLevel(level)
    per_epoch = res.steps // res.epochs
    return statistics.median(float(h["seconds"]) / per_epoch for h in res.history[1:])


def probe_step_seconds(cfg, device, dtype, steps: int = PROBE_STEPS) -> float:
    """Seconds per training step of ``cfg``'s model on ``device`` in float32 (``dtype`` None)
    or in the device's mixed precision (any other ``dtype``): :func:`measure_step_seconds` of
    one warm-up epoch and one timed epoch of ``steps`` steps on synthetic corridor frames at
    IFR's density."""
    from sim2radar.datasets import make_door_frames

    bs = cfg.optimization.batch_size
    frames = make_door_frames(steps * bs, seed=0, points_per_frame=_PROBE_POINTS,
                              num_point_features=cfg.model.num_point_features)
    return measure_step_seconds(cfg.with_updates(runtime={"amp": dtype is not None}), frames,
                                steps_per_epoch=steps, epochs=2, device=device)


def prefers_mixed(float32_s: float, mixed_s: float) -> bool:
    """The rule: mixed precision only when its step is at least :data:`MIN_GAIN` faster."""
    return mixed_s <= (1.0 - MIN_GAIN) * float32_s


def _decide(cfg, device, *, probe: bool) -> PrecisionDecision:
    import torch

    from sim2radar.hardware import cpu_has_native_bf16

    device = torch.device(device)
    name = device_name(device, cfg.runtime.num_threads)
    if device.type == "cpu" and not cpu_has_native_bf16():
        return PrecisionDecision(False, "float32", name, "table",
                                 reason="this CPU has no native bfloat16 (oneDNN would emulate "
                                        "it, slower than float32)")
    mixed = _mixed_dtype(device)
    mixed_name = str(mixed).removeprefix("torch.")
    if not probe:
        return PrecisionDecision(True, mixed_name, name, "rule",
                                 reason=f"not probed yet: {mixed_name} assumed (the sweep "
                                        "probes it before its first run)")
    fp32 = probe_step_seconds(cfg, device, None)
    amp_s = probe_step_seconds(cfg, device, mixed)
    faster = prefers_mixed(fp32, amp_s)
    figures = {"float32": round(fp32, 5), mixed_name: round(amp_s, 5)}
    verdict = (f"{mixed_name} {amp_s:.4f} s/step vs float32 {fp32:.4f} s/step: "
               + (f"at least {MIN_GAIN:.0%} faster, chosen" if faster else
                  f"not {MIN_GAIN:.0%} faster, float32 kept"))
    return PrecisionDecision(faster, mixed_name if faster else "float32", name, "probe",
                             figures, PROBE_STEPS, verdict)


def decide_precision(cfg, device, *, table: str | os.PathLike | None = None,
                     probe: bool = True, known: dict[str, Any] | None = None
                     ) -> PrecisionDecision:
    """What ``cfg.runtime.amp`` means on ``device``.

    ``true``/``false`` are taken as they are (``fixed``). ``auto``: ``known`` (a decision this
    sweep recorded before, :meth:`PrecisionDecision.to_dict`) when it was made for this device,
    else the decision recorded in ``table`` for this device and model, else the table rule (a
    CPU without native bfloat16: float32) or a probe (:func:`probe_step_seconds` of both
    precisions, :data:`MIN_GAIN` rule), written to ``table``. Only a decision that can be
    recorded is measured: without ``table``, or with ``probe=False`` (a plan or cost
    estimate), an unrecorded decision is the ``rule`` (mixed precision where the hardware has
    it), so two calls always agree.
    """
    import torch

    amp = cfg.runtime.amp
    device = torch.device(device)
    name = device_name(device, cfg.runtime.num_threads)
    if amp is not True and amp != "auto":
        return PrecisionDecision(False, "float32", name, "fixed", reason="runtime.amp: false")
    if amp is True:
        mixed = str(_mixed_dtype(device)).removeprefix("torch.")
        return PrecisionDecision(True, mixed, name, "fixed", reason="runtime.amp: true")
    if known and known.get("device") == name and "amp" in known:
        fields = {f.name for f in dataclasses.fields(PrecisionDecision)}
        kept = PrecisionDecision(**{k: v for k, v in known.items() if k in fields})
        # "recorded" names a measurement taken earlier; a decision nothing measured (the
        # table's rule for a CPU without native bfloat16) keeps its own source
        if kept.source in ("probe", "recorded"):
            kept = dataclasses.replace(kept, source="recorded")
        return kept
    path = None
    if table is not None:
        path = Path(table) / f"{_slug(name)}-{_digest(cfg)}.json"
        try:
            doc = json.loads(path.read_text())
            return dataclasses.replace(PrecisionDecision(**doc), source="recorded")
        except (OSError, ValueError, TypeError):
            pass        # none yet, or unreadable: decide again (and rewrite it)
    decision = _decide(cfg, device, probe=probe and table is not None)
    if path is not None and decision.source == "probe":
        from sim2radar.fileio import write_json

        path.parent.mkdir(parents=True, exist_ok=True)
        write_json(path, decision.to_dict())
    return decision
