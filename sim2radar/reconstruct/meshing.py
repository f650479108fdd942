"""Stage 4b: per-segment meshes by depth-grid triangulation, simplified with pymeshlab.

Every 2×2 block of (strided) pixels inside one segment becomes two triangles, unless the block
straddles a depth discontinuity: an edge whose relative depth jump exceeds what a continuous
surface seen at ``max_incidence_deg`` could produce is cut, so no triangle bridges e.g. a door
edge and the wall behind it. The mesh is then decimated by quadric edge collapse (Garland &
Heckbert 1997) with boundary edges heavily weighted, and its faces are turned towards the camera.
"""

from __future__ import annotations

import atexit
import dataclasses
import math
import os
import pickle
import queue
import subprocess
import sys
import threading
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from sim2radar.mesh import MaterialMesh
from sim2radar.reconstruct import meshlab_process
from sim2radar.reconstruct.backproject import finite_rows
from sim2radar.reconstruct.meshlab_process import decimate as _decimate

__all__ = ["MeshingConfig", "grid_triangulate", "simplify_mesh", "segment_meshes",
           "meshlab_processes", "MESHLAB_PROCESSES_ENV"]

#: Environment variable: worker processes that decimate meshes, shared by the process's
#: threads (:func:`meshlab_processes`); ``0`` decimates on one thread of this process.
MESHLAB_PROCESSES_ENV = "SIM2RADAR_MESHLAB_PROCESSES"
#: The default's cap on decimation processes (the default is the usable cores).
MAX_DEFAULT_MESHLAB_PROCESSES = 8


@dataclasses.dataclass(frozen=True)
class MeshingConfig:
    """Options of per-segment meshing.

    Attributes
    ----------
    stride_px : int — pixel step of the triangulation grid (1 = every pixel).
    max_incidence_deg : float [deg] — steepest viewing angle still treated as one surface; sets
        the depth-jump threshold |Δz|/z > tan(θ)·(stride/f) + ``min_jump_rel``.
    min_jump_rel : float — relative depth jump always allowed (noise floor).
    target_faces : int — quadric-decimation target per segment (0 disables simplification).
    min_faces : int — segments with fewer triangles are dropped.
    """

    stride_px: int = 2
    max_incidence_deg: float = 84.0
    min_jump_rel: float = 0.02
    target_faces: int = 400
    min_faces: int = 2

    def __post_init__(self) -> None:
        if self.stride_px < 1:
            raise ValueError(f"meshing.stride_px must be >= 1, got {self.stride_px}")
        if not 0 < self.max_incidence_deg < 90:
            raise ValueError(
                f"meshing.max_incidence_deg must lie in (0, 90), got {self.max_incidence_deg}"
            )


def grid_triangulate(
    points: np.ndarray,
    mask: np.ndarray,
    *,
    stride_px: int = 1,
    focal_px: float,
    max_incidence_deg: float = 84.0,
    min_jump_rel: float = 0.02,
) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate the pixel grid of a point map inside ``mask``, cutting at depth jumps.

    Parameters
    ----------
    points : (H, W, 3) float — camera-frame points [m], NaN where invalid.
    mask : (H, W) bool — pixels of this surface.
    stride_px : int — grid step [px].
    focal_px : float [px] — focal length, sets the angular pixel pitch.
    max_incidence_deg, min_jump_rel : see :class:`MeshingConfig`.

    Returns
    -------
    vertices : (V, 3) float32 [m]; faces : (F, 3) int32 — only referenced vertices are kept.
    """
    s = int(stride_px)
    p = np.asarray(points, dtype=np.float32)[::s, ::s]
    m = np.asarray(mask, dtype=bool)[::s, ::s] & finite_rows(p)
    h, w = m.shape
    if h < 2 or w < 2:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32)
    z = np.where(m, p[..., 2], np.nan)
    thresh = math.tan(math.radians(max_incidence_deg)) * s / focal_px + min_jump_rel

    def ok(za, zb):
        with np.errstate(invalid="ignore"):
            return (np.abs(za - zb) / np.minimum(za, zb)) <= thresh  # NaN -> False

    z00, z01, z10, z11 = z[:-1, :-1], z[:-1, 1:], z[1:, :-1], z[1:, 1:]
    top, bottom = ok(z00, z01), ok(z10, z11)
    left, right = ok(z00, z10), ok(z01, z11)
    diag = ok(z00, z11)
    anti = ok(z01, z10)
    idx = np.arange(h * w).reshape(h, w)
    i00, i01, i10, i11 = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    # split along the 00-11 diagonal when it is continuous, else along 01-10
    use_diag = diag
    t1 = use_diag & top & right  # 00, 01, 11  (image order: clockwise -> flipped later)
    t2 = use_diag & left & bottom  # 00, 11, 10
    t3 = ~use_diag & anti & top & left  # 00, 01, 10
    t4 = ~use_diag & anti & right & bottom  # 01, 11, 10
    faces = np.concatenate([
        np.stack([i00[t1], i01[t1], i11[t1]], -1),
        np.stack([i00[t2], i11[t2], i10[t2]], -1),
        np.stack([i00[t3], i01[t3], i10[t3]], -1),
        np.stack([i01[t4], i11[t4], i10[t4]], -1),
    ]).astype(np.int64)
    if len(faces) == 0:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32)
    used, inverse = np.unique(faces, return_inverse=True)
    vertices = p.reshape(-1, 3)[used]
    return vertices.astype(np.float32), inverse.reshape(-1, 3).astype(np.int32)


def simplify_mesh(
    vertices: np.ndarray, faces: np.ndarray, target_faces: int
) -> tuple[np.ndarray, np.ndarray]:
    """Quadric edge-collapse decimation (pymeshlab) to about ``target_faces`` faces.

    Boundary edges carry a heavy quadric weight (``boundaryweight`` 10) so outlines and holes
    stay where the depth grid put them while straight runs of boundary vertices may collapse;
    planar regions collapse to few triangles (``planarquadric``). It runs in a decimation
    worker process (:func:`meshlab_processes`): the same result as in this process, bit for
    bit.
    """
    return _start_simplify(vertices, faces, target_faces).result()


def meshlab_processes() -> int:
    """Decimation worker processes: ``SIM2RADAR_MESHLAB_PROCESSES`` (an integer >= 0; 0: one
    thread of this process), by default the usable cores, at most
    :data:`MAX_DEFAULT_MESHLAB_PROCESSES`.

    pymeshlab is not thread-safe (:mod:`~sim2radar.reconstruct.meshlab_process`), so each
    process decimates one mesh at a time; several let a frame's segments, and the worlds that
    ``--workers`` runs on threads, decimate side by side. With one thread for all of them the
    worlds queued behind each other's decimations with a core idle (BENCHMARKS.md)."""
    raw = os.environ.get(MESHLAB_PROCESSES_ENV, "").strip()
    if not raw:
        try:
            cores = len(os.sched_getaffinity(0))
        except AttributeError:       # not Linux
            cores = os.cpu_count() or 1
        return max(1, min(MAX_DEFAULT_MESHLAB_PROCESSES, cores))
    try:
        n = int(raw)
        if n < 0:
            raise ValueError
    except ValueError:
        raise ValueError(f"{MESHLAB_PROCESSES_ENV} must be an integer >= 0 (0: decimate on one "
                         f"thread of this process), got {raw!r}") from None
    return n


def _start_simplify(vertices: np.ndarray, faces: np.ndarray, target_faces: int) -> Future:
    """:func:`simplify_mesh` started: a future of ``(vertices, faces)``."""
    future: Future = Future()
    if target_faces <= 0 or len(faces) <= target_faces:
        future.set_result((vertices, faces))
        return future
    args = (np.ascontiguousarray(vertices), np.ascontiguousarray(faces), int(target_faces))
    n = meshlab_processes()
    if n > 0:
        return _decimation_pool(n).submit(args)
    try:
        future.set_result(_on_meshlab_thread(_decimate, *args))
    except Exception as exc:  # noqa: BLE001 - raised by the future's result()
        future.set_exception(exc)
    return future


class _WorkerProcess:
    """One decimation process (``meshlab_process.py``), started on first use and again after
    it ended."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen | None = None

    def decimate(self, args: tuple) -> tuple[np.ndarray, np.ndarray]:
        if self.proc is None or self.proc.poll() is not None:
            self.close()
            # -P: the script's folder is not put on sys.path, where its modules (check.py,
            # inputs.py, pipeline.py, ...) would shadow top-level modules of those names
            self.proc = subprocess.Popen([sys.executable, "-P", meshlab_process.__file__],
                                         stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        proc = self.proc
        try:
            pickle.dump(args, proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
            proc.stdin.flush()
            ok, value = pickle.load(proc.stdout)
        except (EOFError, OSError, pickle.UnpicklingError) as exc:
            self.close()
            raise RuntimeError(
                f"the pymeshlab decimation process (pid {proc.pid}) ended with exit status "
                f"{proc.returncode} while decimating a mesh of {len(args[1])} faces; the next "
                f"mesh starts a new one. To decimate in this process instead, set "
                f"{MESHLAB_PROCESSES_ENV}=0") from exc
        if not ok:
            raise value
        return value

    def close(self) -> None:
        """End the process: its input closed, it leaves; killed if it has not within 5 s."""
        proc, self.proc = self.proc, None
        if proc is None:
            return
        try:
            proc.stdin.close()
        except OSError:
            pass
        try:
            proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        proc.stdout.close()


class _DecimationPool:
    """``size`` decimation processes fed by as many threads of this process: a submitted mesh
    goes to a free process."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._workers = [_WorkerProcess() for _ in range(size)]
        self._free: queue.SimpleQueue = queue.SimpleQueue()
        for worker in self._workers:
            self._free.put(worker)
        self._threads = ThreadPoolExecutor(size, thread_name_prefix="sim2radar-meshlab")

    def submit(self, args: tuple) -> Future:
        return self._threads.submit(self._run, args)

    def _run(self, args: tuple) -> tuple[np.ndarray, np.ndarray]:
        worker = self._free.get()          # never waits: as many threads as processes
        try:
            return worker.decimate(args)
        finally:
            self._free.put(worker)

    def close(self) -> None:
        self._threads.shutdown(wait=True, cancel_futures=True)
        for worker in self._workers:
            worker.close()


_POOL: _DecimationPool | None = None
_POOL_LOCK = threading.Lock()


def _decimation_pool(size: int) -> _DecimationPool:
    """This process's decimation pool of ``size`` processes (made on first use, shared by its
    threads; made again when ``SIM2RADAR_MESHLAB_PROCESSES`` changed)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is None or _POOL.size != size:
            if _POOL is not None:
                _POOL.close()
            _POOL = _DecimationPool(size)
        return _POOL


def _forget_pool_in_child() -> None:
    """A forked child (a DataLoader worker) owns neither its parent's decimation processes
    nor the threads that feed them: it starts its own if it decimates."""
    global _POOL, _POOL_LOCK
    _POOL, _POOL_LOCK = None, threading.Lock()


os.register_at_fork(after_in_child=_forget_pool_in_child)


def _close_pool() -> None:
    """End the decimation processes (at exit; they would also leave when this process's end
    closes their input)."""
    global _POOL
    with _POOL_LOCK:
        pool, _POOL = _POOL, None
    if pool is not None:
        pool.close()


atexit.register(_close_pool)


# With SIM2RADAR_MESHLAB_PROCESSES=0 pymeshlab runs in this process, where it keeps per-thread
# state that crashes the whole process at interpreter exit ("malloc_consolidate(): unaligned
# fastbin chunk", exit status 134) when a worker thread that used it has ended -- e.g. a
# Prefect task-runner thread. Its calls therefore run on one long-lived daemon thread, which
# never ends before the process does.
_MESHLAB_QUEUE: queue.SimpleQueue | None = None
_MESHLAB_LOCK = threading.Lock()


def _meshlab_worker(jobs: queue.SimpleQueue) -> None:
    while True:
        fn, args, result, done = jobs.get()
        try:
            result.append((True, fn(*args)))
        except BaseException as exc:  # noqa: BLE001 - re-raised in the caller's thread
            result.append((False, exc))
        done.set()


def _on_meshlab_thread(fn, *args):
    """Run ``fn(*args)`` on the dedicated pymeshlab thread and return (or raise) its result."""
    global _MESHLAB_QUEUE
    with _MESHLAB_LOCK:
        if _MESHLAB_QUEUE is None:
            _MESHLAB_QUEUE = queue.SimpleQueue()
            threading.Thread(target=_meshlab_worker, args=(_MESHLAB_QUEUE,),
                             name="sim2radar-pymeshlab", daemon=True).start()
    result: list = []
    done = threading.Event()
    _MESHLAB_QUEUE.put((fn, args, result, done))
    done.wait()
    ok, value = result[0]
    if not ok:
        raise value
    return value


def _face_camera(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Reorder each face so that its right-hand normal points towards the camera origin."""
    if len(faces) == 0:
        return faces
    t = vertices[faces].astype(np.float64)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    away = np.sum(n * t.mean(axis=1), axis=1) > 0
    out = faces.copy()
    out[away] = out[away][:, ::-1]
    return out


def segment_meshes(
    points: np.ndarray,
    segment_id: np.ndarray,
    labels: tuple[str, ...] | list[str],
    materials: list[str],
    focal_px: float,
    config: MeshingConfig = MeshingConfig(),
) -> list[MaterialMesh]:
    """One :class:`MaterialMesh` per segment, in the camera frame.

    Parameters
    ----------
    points : (H, W, 3) float — camera-frame points [m], NaN where invalid.
    segment_id : (H, W) int — segment per pixel, −1 unassigned.
    labels : semantic class per segment; materials : material per segment.
    focal_px : float [px] — camera focal length.

    Returns
    -------
    list[MaterialMesh] — named ``seg_<k>_<label>``; segments that give fewer than
    ``config.min_faces`` triangles are skipped.
    """
    seg = np.asarray(segment_id)
    started = []              # every segment's decimation first, so that they run side by side
    try:
        for k, (label, material) in enumerate(zip(labels, materials, strict=True)):
            mask = seg == k
            if not mask.any():
                continue
            v, f = grid_triangulate(
                points, mask, stride_px=config.stride_px, focal_px=focal_px,
                max_incidence_deg=config.max_incidence_deg, min_jump_rel=config.min_jump_rel,
            )
            if len(f) < config.min_faces:
                continue
            started.append((k, label, material, _start_simplify(v, f, config.target_faces)))
        meshes = []
        for k, label, material, simplified in started:
            v, f = simplified.result()
            if len(f) < config.min_faces:
                continue
            f = _face_camera(v, f)
            meshes.append(
                MaterialMesh(v, f, material=material if material else "unknown",
                             name=f"seg_{k}_{label}", semantic=label)
            )
    finally:                  # after a failure the other segments' decimations are not needed
        for *_, simplified in started:
            simplified.cancel()
    return meshes
