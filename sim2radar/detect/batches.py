"""Training batches: augmentation and collation of one epoch, overlapped with the model's step.

    for pts, gt, n in epoch_batches(frames, order, aug_cfg, mcfg, rng, db, device, prefetch=2):
        loss = model.loss(model(pts, n), gt) ...

Each batch is the frames ``order[k*B:(k+1)*B]`` augmented in order with the epoch's one
random generator (GT sampling, flip, rotation, scaling, shuffle), then collated. With
``prefetch > 0`` a background thread prepares the next ``prefetch`` batches while the model
trains on the current one — the same frames, the same draws in the same order, so **the same
batches bit for bit** as preparing each one just before its step (``prefetch=0``; a test
trains both ways and compares every loss). The host's augmentation then leaves the step's
critical path where there is spare compute beside the model (a GPU step, or a CPU with idle
cores); NumPy and PyTorch release the GIL in their kernels. On CUDA the batches are collated
into pinned memory and copied to the device without blocking.

Why a thread and not ``torch.utils.data.DataLoader`` worker processes: workers would each need
their own random stream, so a batch's augmentation would depend on which worker made it or
need a new per-batch seeding — a new order of draws, and results no longer comparable with
the runs already in the store. One producer thread keeps today's stream exactly.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterator, Sequence

import numpy as np
import torch

from sim2radar.detect.augment import GTDatabase, augment_frame

__all__ = ["collate", "epoch_batches"]


def collate(
    points: Sequence[np.ndarray],
    boxes: Sequence[np.ndarray],
    names: Sequence[Sequence[str]],
    class_names: Sequence[str],
    device: torch.device | str = "cpu",
    *,
    pin: bool = False,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Stack frames into the model's inputs (``pin``: page-locked host memory, copied to
    ``device`` without blocking).

    Returns
    -------
    points : (N, 1 + C) float32 — batch index, then the point columns.
    gt_boxes : (B, M_max, 8) float32 — boxes [m, rad] + 1-based class id (0 = padding).
    """
    cols = [np.concatenate([np.full((len(p), 1), b, np.float32), p], axis=1)
            for b, p in enumerate(points)]
    pts = torch.from_numpy(np.concatenate(cols)) if cols else torch.zeros(0, 1)
    m = max([len(b) for b in boxes] + [1])
    gt = np.zeros((len(boxes), m, 8), np.float32)
    for b, (bx, nm) in enumerate(zip(boxes, names, strict=True)):
        ids = [class_names.index(n) + 1 if n in class_names else 0 for n in nm]
        gt[b, : len(bx), :7] = bx
        gt[b, : len(bx), 7] = ids
    gt_t = torch.from_numpy(gt)
    if pin:
        pts, gt_t = pts.pin_memory(), gt_t.pin_memory()
    return pts.to(device, non_blocking=pin), gt_t.to(device, non_blocking=pin)


def _batches(frames, order, batch_size, aug_cfg, mcfg, rng, db, device, pin):
    for start in range(0, len(order), batch_size):
        batch = [frames[i] for i in order[start:start + batch_size]]
        aug = [augment_frame(f, aug_cfg, rng, mcfg.point_cloud_range_m, db) for f in batch]
        pts, gt = collate([a[0] for a in aug], [a[1] for a in aug], [a[2] for a in aug],
                          mcfg.class_names, "cpu" if pin else device, pin=pin)
        yield pts, gt, len(batch)


_DONE = object()


def epoch_batches(frames: Sequence, order: Sequence[int], batch_size: int, aug_cfg, mcfg,
                  rng: np.random.Generator, db: GTDatabase | None, device: torch.device, *,
                  prefetch: int = 0) -> Iterator[tuple[torch.Tensor, torch.Tensor, int]]:
    """The epoch's batches ``(points, gt_boxes, n_frames)`` on ``device``, in ``order``.

    ``prefetch``: batches a background thread prepares ahead (0: each one when asked). An
    exception while preparing a batch is raised here, at that batch; leaving the loop early
    stops the thread.
    """
    pin = prefetch > 0 and device.type == "cuda"
    made = _batches(frames, order, batch_size, aug_cfg, mcfg, rng, db, device, pin)
    if prefetch <= 0:
        yield from made
        return
    ready: queue.Queue = queue.Queue(maxsize=prefetch)
    stop = threading.Event()

    def put(item) -> bool:
        """Queue ``item`` unless the consumer has left; whether it was queued."""
        while not stop.is_set():
            try:
                ready.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in made:
                if not put(item):
                    return
            put(_DONE)
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer, raised there
            put(exc)

    worker = threading.Thread(target=produce, name="sim2radar-batches", daemon=True)
    worker.start()
    try:
        while True:
            item = ready.get()
            if item is _DONE:
                return
            if isinstance(item, BaseException):
                raise item
            pts, gt, n = item
            if pin:
                pts, gt = pts.to(device, non_blocking=True), gt.to(device, non_blocking=True)
            yield pts, gt, n
    finally:
        stop.set()
        worker.join(timeout=5.0)
