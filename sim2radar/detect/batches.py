"""Training batches: augmentation and collation in ``torch.utils.data.DataLoader`` workers.

    with TrainingBatches(frames, 8, aug_cfg, mcfg, db, seed, device, workers=2) as batches:
        for epoch in range(start_epoch, epochs):
            for pts, gt, n in batches.epoch(epoch):
                loss = model.loss(model(pts, n), gt) ...

**Order of random draws** (issue #31; :data:`RANDOM_DRAWS`). Epoch ``e`` of a run with seed
``s`` visits the frames in the order ``numpy.random.default_rng([s, e]).permutation(N)``. Batch
``k`` of the epoch is the frames ``order[k*B:(k+1)*B]``, each augmented in turn (GT sampling,
flip, rotation, scaling, point shuffle: :func:`~sim2radar.detect.augment.augment_frame`) with
the batch's own generator ``default_rng(SeedSequence([s, e], spawn_key=(k,)))`` — the ``k``-th
child of ``SeedSequence([s, e]).spawn``, independent of the order's stream and of every other
batch's — then collated (:func:`collate`). A batch's points and boxes are therefore a function
of ``(s, e, k)`` alone: the same bit for bit whichever worker makes it, for any number of
workers (0 = in this process), any prefetch depth, and after resuming a run at an epoch
boundary (tests/detect/test_batches.py). Before issue #31 one generator per epoch drew the
order and then every batch's augmentation in sequence, which worker processes cannot share;
runs of the same seed made before and after differ, and the order's name is part of the
detector config (:attr:`~sim2radar.detect.config.AugmentConfig.random_draws`), hence of a
sweep run's key.

**Where the work runs.** ``workers = 0``: the batches are made in this process when the loop
asks (the same DataLoader code path, no second loop). ``workers > 0``: that many persistent
worker processes (one torch and, where threadpoolctl is installed, one BLAS thread each, so
they do not oversubscribe the cores the model uses) each prepare ``prefetch_factor`` batches
ahead — across epoch boundaries when told the run's epoch count (``epochs=``, as
:func:`~sim2radar.detect.train.train` does), so an epoch's first batch is ready when the loop
asks for it — and augmentation and collation leave the step's critical path. The frames and the
GT-sampling database reach the workers once per :class:`TrainingBatches`: shared
copy-on-write under the ``fork`` start method (Linux's default before Python 3.14), pickled
once per worker under ``spawn``/``forkserver``. On CUDA the batches are collated into pinned
memory and copied to the device without blocking. How many workers pay off is measured
(BENCHMARKS.md, :func:`resolve_loader_workers`).
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset, Sampler

from sim2radar.detect.augment import GTDatabase, augment_frame

__all__ = [
    "RANDOM_DRAWS",
    "TrainingBatches",
    "batch_generator",
    "collate",
    "epoch_order",
    "make_batch",
    "resolve_loader_workers",
]

#: name of the order of random draws above (the only one this code makes)
RANDOM_DRAWS = "per_batch"
#: DataLoader workers ``"auto"`` gives on CUDA: the host's ~7 ms of augmentation per batch
#: (BENCHMARKS.md) is a fraction of a GPU step, two workers keep up with slack for jitter
CUDA_AUTO_WORKERS = 2


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


def epoch_order(seed: int, epoch: int, n_frames: int) -> np.ndarray:
    """(n_frames,) int64 — the frame order of ``epoch`` (0-based): a permutation drawn from
    ``default_rng([seed, epoch])``."""
    return np.random.default_rng([int(seed), int(epoch)]).permutation(n_frames)


def batch_generator(seed: int, epoch: int, batch: int) -> np.random.Generator:
    """The generator batch ``batch`` of ``epoch`` (both 0-based) draws its augmentation from:
    child ``batch`` of ``SeedSequence([seed, epoch])`` (what ``.spawn`` would give)."""
    seq = np.random.SeedSequence([int(seed), int(epoch)], spawn_key=(int(batch),))
    return np.random.default_rng(seq)


def make_batch(frames: Sequence, order: Sequence[int], batch: int, batch_size: int, aug_cfg,
               mcfg, db: GTDatabase | None, rng: np.random.Generator,
               ) -> tuple[torch.Tensor, torch.Tensor, int]:
    """Batch ``batch`` of an epoch in ``order``: its frames augmented in turn with ``rng``
    and collated on the host; ``(points, gt_boxes, n_frames)`` as :func:`collate` gives."""
    chosen = [frames[i] for i in order[batch * batch_size:(batch + 1) * batch_size]]
    aug = [augment_frame(f, aug_cfg, rng, mcfg.point_cloud_range_m, db) for f in chosen]
    pts, gt = collate([a[0] for a in aug], [a[1] for a in aug], [a[2] for a in aug],
                      mcfg.class_names)
    return pts, gt, len(chosen)


class _Batches(Dataset):
    """Map-style dataset whose item ``(epoch, k)`` is batch ``k`` of ``epoch`` (module
    docstring); what each DataLoader worker holds."""

    def __init__(self, frames, batch_size, aug_cfg, mcfg, db, seed):
        self.frames, self.batch_size, self.aug_cfg = list(frames), int(batch_size), aug_cfg
        self.mcfg, self.db, self.seed = mcfg, db, int(seed)
        self._order: tuple[int, np.ndarray] | None = None

    def __len__(self) -> int:
        return -(-len(self.frames) // self.batch_size)

    def __getitem__(self, key: tuple[int, int]):
        """``(epoch, k, points, gt_boxes, n_frames)``: the batch with its key."""
        epoch, k = key
        if self._order is None or self._order[0] != epoch:  # one permutation per epoch
            self._order = (epoch, epoch_order(self.seed, epoch, len(self.frames)))
        return (epoch, k, *make_batch(self.frames, self._order[1], k, self.batch_size,
                                      self.aug_cfg, self.mcfg, self.db,
                                      batch_generator(self.seed, epoch, k)))


class _RunSampler(Sampler):
    """Yields ``(e, 0) ... (e, n - 1)`` for every epoch ``e`` in ``[first, last)`` as last set
    (in the main process, so persistent workers need no message about which epoch it is): one
    pass over the rest of the run, which the workers prefetch across epoch boundaries."""

    def __init__(self, n_batches: int):
        self.n_batches, self.first, self.last = int(n_batches), 0, 1

    def __len__(self) -> int:
        return self.n_batches * (self.last - self.first)

    def __iter__(self) -> Iterator[tuple[int, int]]:
        return iter([(e, k) for e in range(self.first, self.last) for k in range(self.n_batches)])


def _as_is(item):
    """DataLoader ``collate_fn``: an item is already a whole collated batch."""
    return item


def _init_worker(worker_id: int) -> None:
    """DataLoader ``worker_init_fn``: one torch thread and one BLAS/OpenMP thread per worker,
    so the workers do not oversubscribe the cores the model's threads use; and none of the
    parent's thread-exit hooks.

    A worker forked from a process that ran a Prefect flow inherits the hooks Prefect's
    background services registered with ``threading`` (drain the event and log queues at
    exit). A worker leaving at the end of training ran them, where the services were never
    started: Prefect's drain asserted, the worker exited with status 1, and torch failed the
    training run ("DataLoader worker exited unexpectedly") — every run of a sweep with workers
    (``loader_workers: auto`` gives 2 on CUDA). Those hooks belong to the parent's threads;
    the worker drops them. (``threading._threading_atexits`` is CPython's list behind
    ``threading._register_atexit``; under spawn/forkserver it starts empty anyway.)
    """
    import threading

    hooks = getattr(threading, "_threading_atexits", None)
    if hooks is not None:
        hooks.clear()
    torch.set_num_threads(1)
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional: NumPy's BLAS then keeps its own count (augmentation
        return           # calls no BLAS kernels large enough to start its threads)
    threadpool_limits(1)


def resolve_loader_workers(setting: int | str, device: torch.device) -> int:
    """DataLoader worker processes for ``runtime.loader_workers``: an int as given; ``"auto"``
    0 on a CPU (there the workers only compete with the model's threads for the cores:
    BENCHMARKS.md, issue #31) and :data:`CUDA_AUTO_WORKERS` on CUDA (at most the cores
    but one, at least one)."""
    if setting != "auto":
        return int(setting)
    if device.type != "cuda":
        return 0
    return max(1, min(CUDA_AUTO_WORKERS, (os.cpu_count() or 2) - 1))


class TrainingBatches:
    """The batches of every epoch of one training run (module docstring), made by a
    ``torch.utils.data.DataLoader`` with ``workers`` persistent worker processes.

    Parameters
    ----------
    frames : training frames (their ``points``/``boxes``/``names`` are read, never changed).
    batch_size : frames per batch; the last batch of an epoch may be smaller.
    aug_cfg : :class:`~sim2radar.detect.config.AugmentConfig`.
    mcfg : :class:`~sim2radar.detect.config.ModelConfig` (point-cloud range, class names).
    db : GT-sampling database, or None.
    seed : the run's seed.
    device : where the batches go; on CUDA they are pinned and copied without blocking.
    workers : worker processes (0: made in this process when asked).
    prefetch_factor : batches each worker prepares ahead (``workers > 0``).
    context : multiprocessing start method for the workers (None: the process default).
    epochs : the run's epoch count, or None. Given, the batches stream from the first epoch
        asked for to the last of the run, so the workers prepare the next epoch's first
        batches while this one's last steps run (short epochs, e.g. a small fine-tuning
        fraction's one or two steps, otherwise wait for a batch at every epoch start); None:
        one epoch at a time. The same batches either way.

    Use as a context manager (or call :meth:`close`): leaving it stops the workers. An
    exception raised while a worker makes a batch is raised by :meth:`epoch` at that batch.
    """

    def __init__(self, frames: Sequence, batch_size: int, aug_cfg, mcfg,
                 db: GTDatabase | None, seed: int, device: torch.device | str = "cpu", *,
                 workers: int = 0, prefetch_factor: int = 2, context: str | None = None,
                 epochs: int | None = None):
        if workers < 0:
            raise ValueError(f"workers must be >= 0, got {workers}")
        self.device = torch.device(device)
        self.workers = int(workers)
        self._pin = self.device.type == "cuda"
        self._epochs = epochs
        dataset = _Batches(frames, batch_size, aug_cfg, mcfg, db, seed)
        self._sampler = _RunSampler(len(dataset))
        self._stream: Iterator | None = None
        self._next: tuple[int, int] | None = None   # the key the stream yields next
        parallel = self.workers > 0
        self._loader: DataLoader | None = DataLoader(
            dataset, batch_size=None, sampler=self._sampler, num_workers=self.workers,
            collate_fn=_as_is, pin_memory=self._pin, persistent_workers=parallel,
            prefetch_factor=prefetch_factor if parallel else None,
            worker_init_fn=_init_worker if parallel else None,
            multiprocessing_context=context if parallel else None,
            # each iterator draws a base seed (for the workers' torch seeds, which nothing
            # here uses): from the run's own generator, not torch's global one that runs in
            # other threads of this process share
            generator=torch.Generator().manual_seed(int(seed)))

    def __len__(self) -> int:
        """Batches per epoch."""
        return self._sampler.n_batches

    def epoch(self, epoch: int) -> Iterator[tuple[torch.Tensor, torch.Tensor, int]]:
        """Epoch ``epoch``'s (0-based) batches ``(points, gt_boxes, n_frames)`` on the device,
        in order (:func:`collate`'s shapes)."""
        if self._loader is None:
            raise RuntimeError("TrainingBatches is closed")
        epoch = int(epoch)
        if self._next != (epoch, 0):  # first call, another epoch, or an epoch left unfinished
            self._sampler.first = epoch
            self._sampler.last = max(epoch + 1, self._epochs or 0)
            self._next, self._stream = (epoch, 0), iter(self._loader)
        for k in range(self._sampler.n_batches):
            e, k_got, pts, gt, n = next(self._stream)
            if (e, k_got) != (epoch, k):
                raise RuntimeError(f"batch stream out of order: got ({e}, {k_got}), "
                                   f"expected ({epoch}, {k})")
            self._next = (epoch, k + 1) if k + 1 < self._sampler.n_batches else (epoch + 1, 0)
            if self.device.type != "cpu":
                pts = pts.to(self.device, non_blocking=self._pin)
                gt = gt.to(self.device, non_blocking=self._pin)
            yield pts, gt, n
        if self._next[0] >= self._sampler.last:  # the stream is spent
            self._next = self._stream = None

    def close(self) -> None:
        """Stop the worker processes (idempotent)."""
        loader, self._loader = getattr(self, "_loader", None), None
        it = getattr(loader, "_iterator", None)   # persistent workers live in the iterator
        if it is not None and hasattr(it, "_shutdown_workers"):
            it._shutdown_workers()

    def __enter__(self) -> TrainingBatches:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()
