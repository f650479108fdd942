"""The one place that picks hardware: the Mitsuba variant and the torch device, and the one
way NumPy data enters Dr.Jit (:func:`to_drjit`).

Order of preference is CUDA -> LLVM (CPU, vectorised JIT) -> scalar (CPU, ~25x slower).
``SIM2RADAR_MITSUBA_VARIANT`` and ``SIM2RADAR_TORCH_DEVICE`` override the choice;
``SIM2RADAR_DRJIT_THREADS`` caps Dr.Jit's CPU worker threads per process (e.g. one Dask worker
per core on a shared machine; default: all cores).
"""

from __future__ import annotations

import functools
import logging
import os
import threading
import traceback

import numpy as np

log = logging.getLogger(__name__)

#: Mitsuba variants in order of preference. ``*_ad_rgb`` keeps Dr.Jit's JIT (and AD, unused).
MITSUBA_VARIANTS: tuple[str, ...] = ("cuda_ad_rgb", "llvm_ad_rgb", "scalar_rgb")


def _variant_works(mi, variant: str) -> bool:
    """Set ``variant`` and trace one ray; False if the backend is missing or broken."""
    try:
        mi.set_variant(variant)
        scene = mi.load_dict({"type": "scene", "r": {"type": "rectangle"}})
        ray = mi.Ray3f(mi.Point3f(0, 0, 1), mi.Vector3f(0, 0, -1))
        si = scene.ray_intersect(ray)
        import drjit as dr

        dr.eval(si.t)
        return True
    except Exception as exc:  # noqa: BLE001 - any backend failure means "not usable"
        log.debug("mitsuba variant %s unusable: %s", variant, exc)
        return False


#: Dr.Jit's JIT state is shared by a process's threads: while one thread records a symbolic
#: loop (Mitsuba's render, the tracer's bounce loop), another's ``dr.eval`` of a scattered array
#: is refused ("Variable r4060 remains dirty despite an attempt to evaluate it", a reference
#: frame of a ``--workers 2`` run). The Dr.Jit work of the renderer, the ray tracer and the
#: reconstruction's scene is done one thread at a time (:func:`drjit_serial`); each launch
#: already uses every core through Dr.Jit's own thread pool, and the threads' other work (NumPy,
#: torch, the store) still overlaps. The lock is also held while the Mitsuba variant is chosen
#: (a second thread must not see Mitsuba half-initialised by the first: a ``--workers 2`` run
#: failed a world with "module 'mitsuba' has no attribute 'variants'") and while Mitsuba objects
#: are destroyed (:func:`release_under_lock`).
DRJIT_LOCK = threading.RLock()

#: Mitsuba objects whose owner died while another thread held :data:`DRJIT_LOCK`; the lock's
#: holder destroys them on its way out (:func:`release_under_lock`)
_RELEASED: list = []


def drjit_serial(fn):
    """Decorator: call ``fn`` holding :data:`DRJIT_LOCK` (re-entrant).

    On the way out it destroys the objects handed to :func:`release_under_lock` meanwhile, and
    an exception leaves with its finished frames' locals cleared, so the Dr.Jit values they held
    die here, under the lock, and not wherever the exception is handled."""
    @functools.wraps(fn)
    def serial(*args, **kwargs):
        with DRJIT_LOCK:
            try:
                return fn(*args, **kwargs)
            except BaseException as exc:
                traceback.clear_frames(exc.__traceback__)
                raise
            finally:
                _destroy_released()
    return serial


def release_under_lock(obj) -> None:
    """Destroy ``obj`` (anything holding Mitsuba objects) while holding :data:`DRJIT_LOCK`.

    A Mitsuba scene, shape, BSDF or texture is registered with Dr.Jit for its virtual calls;
    destroying one unregisters it, and a thread doing that while another records a symbolic
    call over the same registry (Mitsuba's render) hung or crashed the process: the recorder's
    error path waited for the GIL, held by the destroyer spinning on Dr.Jit's state lock (a
    ``--workers 2`` world generation hung there; ``tests/worlds/test_threads.py`` has the race). So an
    owner that dies hands its Mitsuba objects here: they are destroyed now when no other thread
    holds the lock (a one-thread program sees no difference), else by the lock's holder when its
    :func:`drjit_serial` call ends (or, handed over in the instant it was leaving, by the next
    call or release). This never blocks, so it is safe in ``__del__`` and weakref
    callbacks, which run wherever the last reference is dropped.

    Plain Dr.Jit arrays (and NumPy or torch views of them) are not routed here: they are not in
    the registry, and Dr.Jit frees them under its own state lock (from its design; the race test
    drops scenes, not arrays)."""
    _RELEASED.append(obj)
    del obj
    _destroy_released()


def _destroy_released() -> None:
    """Destroy the objects handed to :func:`release_under_lock`, if the lock can be had."""
    if not _RELEASED or not DRJIT_LOCK.acquire(blocking=False):
        return
    try:
        while _RELEASED:
            _RELEASED.pop()  # the last reference: destroyed here, under the lock
    finally:
        DRJIT_LOCK.release()


class ReleasedUnderLock:
    """Base of an object that owns Mitsuba objects: when it dies, its attributes go to
    :func:`release_under_lock`, so whichever thread drops it last, they die under the lock."""

    def __del__(self) -> None:
        release_under_lock(dict(vars(self)))


@drjit_serial
def mitsuba_variant(prefer: str | None = None) -> str:
    """Select, activate and return the fastest working Mitsuba variant.

    Parameters
    ----------
    prefer : str, optional
        A variant name to try first (also read from ``SIM2RADAR_MITSUBA_VARIANT``).
        If it is set explicitly and does not work, this raises instead of falling back.

    Returns
    -------
    str
        The active variant, e.g. ``"llvm_ad_rgb"``.
    """
    return _choose_variant(prefer)


@functools.cache
def _choose_variant(prefer: str | None) -> str:
    try:
        import mitsuba as mi
    except ImportError as exc:  # pragma: no cover - mitsuba is a hard dependency
        raise ImportError("mitsuba is not installed: run `make setup`") from exc

    _apply_drjit_threads()
    forced = prefer or os.environ.get("SIM2RADAR_MITSUBA_VARIANT")
    if forced:
        if forced not in mi.variants():
            raise ValueError(
                f"SIM2RADAR_MITSUBA_VARIANT={forced!r} is not a compiled Mitsuba variant; "
                f"choose one of {mi.variants()}"
            )
        if not _variant_works(mi, forced):
            raise RuntimeError(
                f"Mitsuba variant {forced!r} failed to trace a ray. LLVM variants need "
                "libllvm19 (`apt-get install -y libllvm19`); CUDA variants need a GPU."
            )
        log.info("mitsuba variant: %s (forced)", forced)
        return forced

    for variant in MITSUBA_VARIANTS:
        if variant in mi.variants() and _variant_works(mi, variant):
            if variant.startswith("scalar"):
                log.warning(
                    "mitsuba: falling back to %s (~25x slower). Install libllvm19 "
                    "(`apt-get install -y libllvm19`) for the LLVM variant.",
                    variant,
                )
            else:
                log.info("mitsuba variant: %s", variant)
            return variant
    raise RuntimeError("no Mitsuba variant works on this machine")


# the cache's own handles, as on a functools.cache function (tests read whether it is set)
mitsuba_variant.cache_info = _choose_variant.cache_info      # type: ignore[attr-defined]
mitsuba_variant.cache_clear = _choose_variant.cache_clear    # type: ignore[attr-defined]


def _apply_drjit_threads() -> None:
    """Honour ``SIM2RADAR_DRJIT_THREADS`` (a positive integer) for Dr.Jit's CPU thread pool."""
    value = os.environ.get("SIM2RADAR_DRJIT_THREADS")
    if not value:
        return
    try:
        n = int(value)
        if n < 1:
            raise ValueError
    except ValueError:
        raise ValueError(
            f"SIM2RADAR_DRJIT_THREADS must be a positive integer, got {value!r}"
        ) from None
    import drjit as dr

    dr.set_thread_count(n)
    log.info("drjit: %d CPU threads", n)


#: Slack after every NumPy buffer handed to Dr.Jit [bytes]: 4x the widest vector packet (64 B).
DRJIT_SLACK_BYTES = 256


#: Alignment of the buffers :func:`to_drjit` hands to Dr.Jit [bytes] (a cache line, the widest
#: vector load).
DRJIT_ALIGN_BYTES = 64


@functools.cache
def _blas_controller():
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:       # a --no-deps install (the GPU check's): BLAS keeps its count
        return None
    return ThreadpoolController()


def one_blas_thread():
    """Context manager: NumPy's BLAS on one thread inside it (threadpoolctl). After a threaded
    product OpenBLAS's idle threads spin for a while, and on a machine whose cores Dr.Jit's
    next kernel wants (the ray tracer's, one frame after another) that spinning slowed the
    tracing of the next frame by ~20 %; the tracer's detection products are small enough for
    one thread (``benchmarks radar``)."""
    import contextlib

    ctl = _blas_controller()
    return contextlib.nullcontext() if ctl is None else ctl.limit(limits=1, user_api="blas")


def to_drjit(array_type, values, dtype=None):
    """A Dr.Jit array of type ``array_type`` holding ``values``, safe for Dr.Jit kernels.

    Dr.Jit's LLVM backend does not copy a contiguous NumPy array: the Dr.Jit array keeps the
    NumPy buffer, and its kernels load it in whole vector packets (16 float32 with AVX-512),
    so they read past the end of a buffer whose length is not a multiple of the packet. NumPy
    allocates exactly: when the buffer ends where a mapping ends the kernel faults (reproduced:
    161 float32 ending at a guard page -> SIGSEGV; 160 or 176 -> fine). The factory died that
    way about once in 50 killed runs (the visibility query's ray origins; the heap layout after
    a SIGTERM made it likelier). Here ``values`` are copied into a fresh buffer with
    :data:`DRJIT_SLACK_BYTES` after its end, which the Dr.Jit array keeps (nothing else holds it,
    so nothing else can change it either). The buffer starts on a :data:`DRJIT_ALIGN_BYTES`
    boundary: Dr.Jit compiles a NumPy input's load with the alignment the pointer happens to
    have (``align 64`` or ``align 1``), so buffers of varying alignment made the same kernel
    compile again (0-3 recompilations per traced frame, ~0.1 s each, with a new seed per
    frame); aligned, every frame reuses the compiled kernels.

    Parameters
    ----------
    array_type : a Dr.Jit array type, flat (``mi.Float``, ``mi.UInt32``) or with components
        (``mi.Point3f``: ``values`` is then ``(components, N)``).
    values : array-like
    dtype : NumPy dtype of the copy (default: that of ``values``)

    Returns
    -------
    ``array_type`` instance
    """
    import drjit as dr

    a = np.asarray(values, dtype=dtype)
    if dr.depth_v(array_type) > 1:
        if a.ndim != 2 or a.shape[0] != dr.size_v(array_type):
            raise ValueError(f"{array_type.__name__} needs ({dr.size_v(array_type)}, N) values, "
                             f"got shape {a.shape}")
        return array_type(*(to_drjit(dr.value_t(array_type), row) for row in a))
    flat = a.reshape(-1)
    slack = -(-DRJIT_SLACK_BYTES // flat.dtype.itemsize)
    n_bytes = (flat.size + slack) * flat.dtype.itemsize
    raw = np.zeros(n_bytes + DRJIT_ALIGN_BYTES, dtype=np.uint8)
    start = -raw.ctypes.data % DRJIT_ALIGN_BYTES
    buf = raw[start:start + n_bytes].view(flat.dtype)
    buf[: flat.size] = flat
    return array_type(buf[: flat.size])


def torch_device(prefer: str | None = None):
    """Return the torch device to use: ``prefer`` / ``SIM2RADAR_TORCH_DEVICE``, else CUDA if
    available, else CPU."""
    import torch

    name = prefer or os.environ.get("SIM2RADAR_TORCH_DEVICE")
    if name:
        return torch.device(name)
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


def has_cuda() -> bool:
    """True if torch sees a CUDA GPU (used by tests to skip ``gpu``-marked cases)."""
    try:
        import torch

        return torch.cuda.is_available()
    except ImportError:  # pragma: no cover
        return False


#: /proc/cpuinfo flags of CPUs with native bfloat16 matrix arithmetic (AVX-512 BF16, Intel AMX)
CPU_BF16_FLAGS = ("avx512_bf16", "amx_bf16")


@functools.lru_cache(maxsize=1)
def cpu_has_native_bf16() -> bool:
    """True when this CPU multiplies bfloat16 natively (``avx512_bf16`` or ``amx_bf16`` in
    ``/proc/cpuinfo``; False where that file does not exist). Without it, oneDNN emulates
    bfloat16 and mixed precision is slower than float32."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("flags"):
                    flags = set(line.split(":", 1)[1].split())
                    return any(f in flags for f in CPU_BF16_FLAGS)
    except OSError:
        pass
    return False


def autocast_dtype(device, amp: bool | str):
    """The autocast dtype of mixed-precision training on ``device``, or None for float32.

    ``amp``: False (float32), True (mixed precision: bfloat16 on a CPU, bfloat16 on a CUDA GPU
    that supports it, else float16), or ``"auto"`` (True where it is fast: every CUDA GPU, and
    CPUs with native bfloat16, :func:`cpu_has_native_bf16`; float32 elsewhere).
    """
    import torch

    device = torch.device(device)
    if amp is False or amp is None:
        return None
    if amp not in (True, "auto"):
        raise ValueError(f"amp must be true, false or 'auto', got {amp!r}")
    if device.type == "cuda":
        return torch.bfloat16 if torch.cuda.is_bf16_supported() else torch.float16
    if device.type == "cpu" and (amp is True or cpu_has_native_bf16()):
        return torch.bfloat16
    return None
