"""Stage 4b: per-segment meshes by depth-grid triangulation, simplified with pymeshlab.

Every 2×2 block of (strided) pixels inside one segment becomes two triangles, unless the block
straddles a depth discontinuity: an edge whose relative depth jump exceeds what a continuous
surface seen at ``max_incidence_deg`` could produce is cut, so no triangle bridges e.g. a door
edge and the wall behind it. The mesh is then decimated by quadric edge collapse (Garland &
Heckbert 1997) with boundary edges heavily weighted, and its faces are turned towards the camera.
"""

from __future__ import annotations

import dataclasses
import math
import queue
import threading

import numpy as np

from sim2radar.mesh import MaterialMesh
from sim2radar.reconstruct.backproject import finite_rows

__all__ = ["MeshingConfig", "grid_triangulate", "simplify_mesh", "segment_meshes"]


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
    planar regions collapse to few triangles (``planarquadric``).
    """
    if target_faces <= 0 or len(faces) <= target_faces:
        return vertices, faces
    return _on_meshlab_thread(_decimate, vertices, faces, int(target_faces))


def _decimate(vertices: np.ndarray, faces: np.ndarray, target_faces: int):
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.asarray(vertices, np.float64), np.asarray(faces, np.int32)))
    ms.meshing_decimation_quadric_edge_collapse(
        targetfacenum=target_faces,
        preserveboundary=False,
        boundaryweight=10.0,
        preservenormal=True,
        planarquadric=True,
        qualitythr=0.3,
        autoclean=True,
    )
    out = ms.current_mesh()
    return out.vertex_matrix().astype(np.float32), out.face_matrix().astype(np.int32)


# pymeshlab keeps per-thread state that crashes the whole process at interpreter exit
# ("malloc_consolidate(): unaligned fastbin chunk", exit status 134) when a worker thread that
# used it has ended -- e.g. a Prefect task-runner thread. Every pymeshlab call therefore runs on
# one long-lived daemon thread, which never ends before the process does.
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
    meshes = []
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
        v, f = simplify_mesh(v, f, config.target_faces)
        if len(f) < config.min_faces:
            continue
        f = _face_camera(v, f)
        meshes.append(
            MaterialMesh(v, f, material=material if material else "unknown",
                         name=f"seg_{k}_{label}", semantic=label)
        )
    return meshes
