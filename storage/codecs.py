"""NumPy <-> Arrow conversions for array columns, and codecs for the core artifact tables.

Variable-length arrays become Arrow list columns whose flat values are one contiguous buffer,
so reading back is a zero-copy reshape (no Python loop over points).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pyarrow as pa

__all__ = [
    "ragged_column",
    "ragged_arrays",
    "fixed_rows_column",
    "fixed_rows",
    "meshes_to_table",
    "meshes_from_table",
    "radar_frames_to_table",
    "RadarPointsFrame",
    "radar_frames_from_table",
]


# ---------------------------------------------------------------------------------------------
# Generic array columns
# ---------------------------------------------------------------------------------------------
def ragged_column(arrays: Sequence[np.ndarray], value_type: pa.DataType) -> pa.ListArray:
    """One list cell per array. ``(N_i,)`` arrays give ``list<value_type>``; ``(N_i, k)`` arrays
    give ``list<fixed_size_list<value_type, k>>``.

    Parameters
    ----------
    arrays : sequence of (N_i,) or (N_i, k) arrays, one per row (k equal for all rows)
    value_type : pyarrow numeric type of the elements, e.g. ``pa.float32()``
    """
    np_dtype = value_type.to_pandas_dtype()
    arrays = [np.asarray(a) for a in arrays]
    ndims = {a.ndim for a in arrays}
    if len(ndims) > 1:
        raise ValueError(f"ragged_column: rows must all be 1-D or all 2-D, got ndims {ndims}")
    ndim = ndims.pop() if ndims else 1
    if ndim == 2:
        widths = {a.shape[1] for a in arrays}
        if len(widths) != 1:
            raise ValueError(f"ragged_column: rows must share their second dimension, got {widths}")
        width = widths.pop()
    elif ndim != 1:
        raise ValueError(f"ragged_column: rows must be 1-D or 2-D arrays, got {ndim}-D")
    lengths = np.array([len(a) for a in arrays], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32)
    flat = (
        np.concatenate([a.reshape(-1) for a in arrays]).astype(np_dtype, copy=False)
        if arrays
        else np.zeros(0, dtype=np_dtype)
    )
    values: pa.Array = pa.array(flat, type=value_type)
    if ndim == 2:
        values = pa.FixedSizeListArray.from_arrays(values, width)
    return pa.ListArray.from_arrays(pa.array(offsets, type=pa.int32()), values)


def _combine(col: pa.ChunkedArray | pa.Array) -> pa.Array:
    if isinstance(col, pa.ChunkedArray):
        return col.combine_chunks() if col.num_chunks != 1 else col.chunk(0)
    return col


def ragged_arrays(col: pa.ChunkedArray | pa.Array) -> list[np.ndarray]:
    """Inverse of :func:`ragged_column`: one NumPy array per row ((N_i,) or (N_i, k))."""
    arr = _combine(col)
    if arr.null_count:
        raise ValueError("ragged_arrays: column has null rows")
    offsets = arr.offsets.to_numpy()
    values = arr.values
    width = None
    if pa.types.is_fixed_size_list(values.type):
        width = values.type.list_size
        # slice-aware flattening of the fixed-size child
        values = values.flatten()
    flat = values.to_numpy(zero_copy_only=False)
    if width is not None:
        flat = flat.reshape(-1, width)
    return [flat[offsets[i] : offsets[i + 1]] for i in range(len(arr))]


def fixed_rows_column(matrix: np.ndarray, value_type: pa.DataType) -> pa.FixedSizeListArray:
    """An (R, k) matrix (or (R, a, b), flattened row-major) as ``fixed_size_list<value_type, k>``."""
    m = np.asarray(matrix)
    m = m.reshape(len(m), -1).astype(value_type.to_pandas_dtype(), copy=False)
    return pa.FixedSizeListArray.from_arrays(pa.array(m.reshape(-1), type=value_type), m.shape[1])


def fixed_rows(col: pa.ChunkedArray | pa.Array) -> np.ndarray:
    """Inverse of :func:`fixed_rows_column`: an (R, k) array."""
    arr = _combine(col)
    width = arr.type.list_size
    return arr.flatten().to_numpy(zero_copy_only=False).reshape(-1, width)


# ---------------------------------------------------------------------------------------------
# scene_meshes
# ---------------------------------------------------------------------------------------------
def meshes_to_table(meshes) -> pa.Table:
    """A list of :class:`sim2radar.mesh.MaterialMesh` as a ``scene_meshes`` table."""
    meshes = list(meshes)
    return pa.table(
        {
            "name": pa.array([m.name for m in meshes], pa.string()),
            "material": pa.array([m.material for m in meshes], pa.string()),
            "semantic": pa.array([m.semantic for m in meshes], pa.string()),
            "vertices_m": ragged_column([m.vertices for m in meshes], pa.float32()),
            "faces": ragged_column([m.faces for m in meshes], pa.int32()),
        }
    )


def meshes_from_table(table: pa.Table):
    """A ``scene_meshes`` table back to a list of :class:`~sim2radar.mesh.MaterialMesh`."""
    from sim2radar.mesh import MaterialMesh

    verts = ragged_arrays(table.column("vertices_m"))
    faces = ragged_arrays(table.column("faces"))
    names = table.column("name").to_pylist()
    materials = table.column("material").to_pylist()
    semantics = table.column("semantic").to_pylist()
    return [
        MaterialMesh(v, f, material=m, name=n, semantic=s)
        for v, f, m, n, s in zip(verts, faces, materials, names, semantics, strict=True)
    ]


# ---------------------------------------------------------------------------------------------
# radar_points
# ---------------------------------------------------------------------------------------------
class RadarPointsFrame:
    """One decoded row of a ``radar_points`` table.

    Attributes
    ----------
    scene_id : str
    frame_index : int
    radar_to_world : (4, 4) float64 — radar-to-world transform [m]
    points : (N, 4) float32 — x, y, z [m] (radar frame), intensity [dB]
    boxes : (M, 7) float32 — x y z dx dy dz [m], heading [rad], radar frame
    box_labels : list[str] — (M,) class names
    sim_seconds : float [s]
    """

    __slots__ = (
        "scene_id",
        "frame_index",
        "radar_to_world",
        "points",
        "boxes",
        "box_labels",
        "sim_seconds",
    )

    def __init__(self, scene_id, frame_index, radar_to_world, points, boxes, box_labels, sim_seconds):
        self.scene_id = scene_id
        self.frame_index = frame_index
        self.radar_to_world = radar_to_world
        self.points = points
        self.boxes = boxes
        self.box_labels = box_labels
        self.sim_seconds = sim_seconds

    def __repr__(self) -> str:
        return (
            f"RadarPointsFrame(scene_id={self.scene_id!r}, frame_index={self.frame_index}, "
            f"points={self.points.shape}, boxes={self.boxes.shape})"
        )


def radar_frames_to_table(
    *,
    scene_id: str,
    radar_to_world: Sequence[np.ndarray],
    points: Sequence[np.ndarray],
    boxes: Sequence[np.ndarray] | None = None,
    box_labels: Sequence[Sequence[str]] | None = None,
    sim_seconds: Sequence[float] | None = None,
) -> pa.Table:
    """Build a ``radar_points`` table, one row per frame.

    Parameters
    ----------
    scene_id : str
    radar_to_world : K arrays (4, 4) [m] — radar pose per frame
    points : K arrays (N_k, 4) float32 — x, y, z [m] radar frame, intensity [dB]
    boxes : K arrays (M_k, 7), optional — boxes in the radar frame (``vocab.BOX_FIELDS``)
    box_labels : K lists of M_k class names, optional (default ``"door"``)
    sim_seconds : K floats [s], optional
    """
    n = len(points)
    pts = [np.asarray(p, dtype=np.float32).reshape(-1, 4) for p in points]
    if len(radar_to_world) != n:
        raise ValueError(f"radar_to_world has {len(radar_to_world)} poses for {n} frames")
    boxes = [np.zeros((0, 7), np.float32)] * n if boxes is None else boxes
    if len(boxes) != n:
        raise ValueError(f"boxes has {len(boxes)} entries for {n} frames")
    boxes = [np.asarray(b, dtype=np.float32).reshape(-1, 7) for b in boxes]
    if box_labels is None:
        box_labels = [["door"] * len(b) for b in boxes]
    for k, (b, lab) in enumerate(zip(boxes, box_labels, strict=True)):
        if len(lab) != len(b):
            raise ValueError(f"frame {k}: {len(lab)} box labels for {len(b)} boxes")
    sim_seconds = [0.0] * n if sim_seconds is None else list(sim_seconds)
    return pa.table(
        {
            "scene_id": pa.array([scene_id] * n, pa.string()),
            "frame_index": pa.array(np.arange(n, dtype=np.int32)),
            "radar_to_world": fixed_rows_column(
                np.stack([np.asarray(p, np.float64).reshape(4, 4) for p in radar_to_world])
                if n
                else np.zeros((0, 16)),
                pa.float64(),
            ),
            "n_points": pa.array([len(p) for p in pts], pa.int32()),
            "x_m": ragged_column([p[:, 0] for p in pts], pa.float32()),
            "y_m": ragged_column([p[:, 1] for p in pts], pa.float32()),
            "z_m": ragged_column([p[:, 2] for p in pts], pa.float32()),
            "intensity_db": ragged_column([p[:, 3] for p in pts], pa.float32()),
            "boxes": ragged_column(boxes, pa.float32()),
            "box_labels": pa.array([list(lab) for lab in box_labels], pa.list_(pa.string())),
            "sim_seconds": pa.array(sim_seconds, pa.float64()),
        }
    )


def radar_frames_from_table(table: pa.Table) -> list[RadarPointsFrame]:
    """Decode a ``radar_points`` table into one :class:`RadarPointsFrame` per row."""
    xs, ys, zs, its = (
        ragged_arrays(table.column(c)) for c in ("x_m", "y_m", "z_m", "intensity_db")
    )
    boxes = ragged_arrays(table.column("boxes"))
    poses = fixed_rows(table.column("radar_to_world")).reshape(-1, 4, 4)
    out = []
    for i, (sid, fidx, labels, secs) in enumerate(
        zip(
            table.column("scene_id").to_pylist(),
            table.column("frame_index").to_pylist(),
            table.column("box_labels").to_pylist(),
            table.column("sim_seconds").to_pylist(),
            strict=True,
        )
    ):
        pts = np.stack([xs[i], ys[i], zs[i], its[i]], axis=1).astype(np.float32, copy=False)
        out.append(
            RadarPointsFrame(
                sid, fidx, poses[i], pts, boxes[i].reshape(-1, 7), labels, secs
            )
        )
    return out
