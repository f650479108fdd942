"""Codec of ``dataset_frames`` artifacts: :class:`~sim2radar.factory.frames.DatasetFrame` <->
one-row Arrow table (schema ``dataset_frames`` in :mod:`sim2radar.storage.schemas`)."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa

from sim2radar.factory.frames import DatasetFrame
from sim2radar.fileio import jsonable
from sim2radar.storage.codecs import ragged_arrays, ragged_column

__all__ = ["dataset_frame_to_table", "dataset_frame_from_table"]


def dataset_frame_to_table(f: DatasetFrame) -> pa.Table:
    """One-row table of a dataset frame (validated by the store on write)."""
    pts = np.asarray(f.points, np.float32).reshape(-1, 4)
    fidelity = (f.stats.get("radar") or {}).get("fidelity", "raytrace")
    return pa.table({
        "frame_id": [f.frame_id],
        "world_id": [f.world_id],
        "seed": pa.array([f.seed], pa.int64()),
        "frame_index": pa.array([f.frame_index], pa.int32()),
        "geometry": [f.geometry],
        "radar_fidelity": [str(fidelity)],
        "radar_to_world": pa.array([np.asarray(f.radar_to_world, np.float64).ravel()],
                                   pa.list_(pa.float64(), 16)),
        "n_points": pa.array([len(pts)], pa.int32()),
        "x_m": ragged_column([pts[:, 0]], pa.float32()),
        "y_m": ragged_column([pts[:, 1]], pa.float32()),
        "z_m": ragged_column([pts[:, 2]], pa.float32()),
        "intensity_db": ragged_column([pts[:, 3]], pa.float32()),
        "doppler_mps": ragged_column([np.asarray(f.doppler_mps, np.float32).reshape(-1)],
                                     pa.float32()),
        "boxes": ragged_column([np.asarray(f.boxes, np.float32).reshape(-1, 7)], pa.float32()),
        "box_labels": pa.array([list(f.box_labels)], pa.list_(pa.string())),
        "label_visibility": ragged_column([np.asarray(f.label_visibility, np.float32)],
                                          pa.float32()),
        "gt_boxes": ragged_column([np.asarray(f.gt_boxes, np.float32).reshape(-1, 7)],
                                  pa.float32()),
        "gt_door_index": ragged_column([np.asarray(f.gt_door_index, np.int32)], pa.int32()),
        "gt_points_near": ragged_column([np.asarray(f.gt_points_near, np.int32)], pa.int32()),
        "gt_visibility": ragged_column([np.asarray(f.gt_visibility, np.float32)], pa.float32()),
        "n_triangles": pa.array([int(f.n_triangles)], pa.int64()),
        "timings_s": pa.array([list(f.timings_s.items())], pa.map_(pa.string(), pa.float64())),
        "stats_json": [json.dumps(jsonable(f.stats), sort_keys=True)],
        "surface_offset_m": ragged_column([_offsets(f, len(pts))], pa.float32()),
    })


def _offsets(f: DatasetFrame, n: int) -> np.ndarray:
    """The frame's surface offsets, NaN for each point when the geometry is unknown."""
    if f.surface_offset_m is None:
        return np.full(n, np.nan, np.float32)
    off = np.asarray(f.surface_offset_m, np.float32).reshape(-1)
    if len(off) != n:
        raise ValueError(f"{f.frame_id}: {len(off)} surface offsets for {n} points")
    return off


def dataset_frame_from_table(t: pa.Table) -> DatasetFrame:
    """Decode a one-row ``dataset_frames`` table."""
    def col(name: str) -> np.ndarray:
        return ragged_arrays(t.column(name))[0]

    row = t.select(["frame_id", "world_id", "seed", "frame_index", "geometry", "box_labels",
                    "n_triangles", "timings_s", "stats_json"]).to_pylist()[0]
    x, y, z, i = (col(c) for c in ("x_m", "y_m", "z_m", "intensity_db"))
    return DatasetFrame(
        frame_id=row["frame_id"], world_id=row["world_id"], seed=int(row["seed"]),
        frame_index=int(row["frame_index"]), geometry=row["geometry"],
        radar_to_world=np.asarray(t.column("radar_to_world")[0].as_py()).reshape(4, 4),
        points=np.stack([x, y, z, i], axis=1).astype(np.float32).reshape(-1, 4),
        doppler_mps=np.asarray(col("doppler_mps"), np.float32).reshape(-1),
        boxes=col("boxes").reshape(-1, 7).astype(np.float32),
        box_labels=tuple(row["box_labels"]),
        label_visibility=np.asarray(col("label_visibility"), np.float32).reshape(-1),
        gt_boxes=col("gt_boxes").reshape(-1, 7).astype(np.float32),
        gt_door_index=np.asarray(col("gt_door_index"), np.int32),
        gt_points_near=np.asarray(col("gt_points_near"), np.int32),
        gt_visibility=np.asarray(col("gt_visibility"), np.float32).reshape(-1),
        n_triangles=int(row["n_triangles"]), timings_s=dict(row["timings_s"]),
        stats=json.loads(row["stats_json"]),
        surface_offset_m=_decoded_offsets(col("surface_offset_m")),
    )


def _decoded_offsets(off: np.ndarray) -> np.ndarray | None:
    off = np.asarray(off, np.float32).reshape(-1)
    return None if len(off) and np.isnan(off).all() else off
