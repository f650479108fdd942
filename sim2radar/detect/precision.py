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
import os
import statistics
import time
from pathlib import Path
from typing import Any

__all__ = ["MIN_GAIN", "PROBE_STEPS", "PrecisionDecision", "decide_precision", "device_name",
           "probe_step_seconds"]

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


def device_name(device) -> str:
    """A stable name of ``device``'s hardware: the GPU's name for CUDA, the CPU model and the
    thread count for a CPU."""
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
    return f"cpu:{model or os.uname().machine}:{torch.get_num_threads()} threads"


def _mixed_dtype(device) -> Any:
    """The autocast dtype mixed precision would use on ``device``."""
    from sim2radar.hardware import autocast_dtype

    return autocast_dtype(device, True)


def _digest(cfg) -> str:
    doc = {"model": cfg.model.model_dump(mode="json"),
           "augmentation": cfg.augmentation.model_dump(mode="json"),
           "batch_size": cfg.optimization.batch_size}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:16]


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-." else "_" for c in text)[:80]


def probe_step_seconds(cfg, device, dtype, steps: int = PROBE_STEPS) -> float:
    """Median seconds per training step of ``cfg``'s model on ``device`` with autocast to
    ``dtype`` (None: float32): batch ``cfg.optimization.batch_size`` of synthetic corridor
    frames, augmentation, collation, forward, loss, backward and AdamW, one warm-up step."""
    import numpy as np
    import torch

    from sim2radar.datasets import make_door_frames
    from sim2radar.detect.augment import augment_frame, build_gt_database
    from sim2radar.detect.model import PointPillars
    from sim2radar.detect.train import collate

    device = torch.device(device)
    mcfg, bs = cfg.model, cfg.optimization.batch_size
    frames = make_door_frames(2 * bs, seed=0, points_per_frame=_PROBE_POINTS,
                              num_point_features=mcfg.num_point_features)
    db = build_gt_database(frames, mcfg.class_names, cfg.augmentation.min_points_in_gt)
    rng = np.random.default_rng(0)
    with torch.random.fork_rng(devices=[device] if device.type == "cuda" else []):
        torch.manual_seed(0)
        model = PointPillars(mcfg).to(device).train()
    opt = torch.optim.AdamW(model.parameters(), lr=1e-4)
    scaler = torch.amp.GradScaler("cuda", enabled=dtype == torch.float16)
    times = []
    for i in range(steps + 1):
        batch = [frames[(i * bs + k) % len(frames)] for k in range(bs)]
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        t0 = time.perf_counter()
        aug = [augment_frame(f, cfg.augmentation, rng, mcfg.point_cloud_range_m, db)
               for f in batch]
        pts, gt = collate([a[0] for a in aug], [a[1] for a in aug], [a[2] for a in aug],
                          mcfg.class_names, device)
        with torch.autocast(device.type, dtype=dtype, enabled=dtype is not None):
            out = model(pts, len(batch))
        loss, _ = model.loss(out, gt)
        opt.zero_grad(set_to_none=True)
        scaler.scale(loss).backward()
        scaler.step(opt)
        scaler.update()
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        times.append(time.perf_counter() - t0)
    return statistics.median(times[1:])


def _decide(cfg, device, *, probe: bool) -> PrecisionDecision:
    import torch

    from sim2radar.hardware import cpu_has_native_bf16

    device = torch.device(device)
    name = device_name(device)
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
    faster = amp_s <= (1.0 - MIN_GAIN) * fp32
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
    if amp is not True and amp != "auto":
        return PrecisionDecision(False, "float32", device_name(device), "fixed",
                                 reason="runtime.amp: false")
    if amp is True:
        mixed = str(_mixed_dtype(device)).removeprefix("torch.")
        return PrecisionDecision(True, mixed, device_name(device), "fixed",
                                 reason="runtime.amp: true")
    if known and known.get("device") == device_name(device) and "amp" in known:
        fields = {f.name for f in dataclasses.fields(PrecisionDecision)}
        return dataclasses.replace(PrecisionDecision(**{k: v for k, v in known.items()
                                                        if k in fields}), source="recorded")
    path = None
    if table is not None:
        path = Path(table) / f"{_slug(device_name(device))}-{_digest(cfg)}.json"
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
