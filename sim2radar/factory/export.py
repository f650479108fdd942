"""A dataset's frames in OpenPCDet's custom layout, split by world (or capture scene), with a
``dataset.json`` that says what the export is: :func:`export_frames`. The factory's tasks read
the frames from the store and call it."""

from __future__ import annotations

import logging
import os
from collections.abc import Iterable, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from sim2radar.datasets import Frame, write_dataset, write_metadata
from sim2radar.datasets.splits import split_groups
from sim2radar.evaluate.fidelity import label_quality
from sim2radar.factory.frames import DatasetFrame
from sim2radar.factory.labels import DEFAULT_POINT_CLOUD_RANGE_M, boxes_in_point_cloud_range
from sim2radar.vocab import id_problem

__all__ = ["export_frames", "point_geometry"]

log = logging.getLogger(__name__)


def export_frames(frames: Iterable[DatasetFrame], export_dir: str | os.PathLike,
                  geometry: str, *, seed: int = 0,
                     label_range_m: Sequence[float] | None = DEFAULT_POINT_CLOUD_RANGE_M,
                     with_doppler: bool = False,
                     splits: dict[str, list[str]] | None = None,
                     metadata: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write the frames of one geometry in OpenPCDet's custom layout with
    :func:`sim2radar.datasets.write_dataset`.

    ``points/<frame_id>.npy`` (N, 4) float32 x, y, z [m], intensity [dB] (+ doppler [m/s] as a
    5th column with ``with_doppler``); ``labels/<frame_id>.txt`` ``x y z dx dy dz heading
    <class>``, only labels whose centre lies in ``label_range_m`` (the detector's point-cloud
    range; None keeps all); ``ImageSets/{train,val,test}.txt`` split by world (seeded,
    :func:`~sim2radar.datasets.splits.split_groups`, or the given ``splits``: split name -> world ids); ``dataset.json``
    (:func:`sim2radar.datasets.write_metadata`): ``metadata`` plus the counts, the label rule,
    the worlds of each split, and for procedural worlds (frames that know the true geometry)
    where the points are (``point_geometry``, :func:`point_geometry`) and how the exported
    labels compare with the true doors the radar sees (``labels_vs_truth``,
    :func:`sim2radar.evaluate.fidelity.label_quality`), both read by the gap report.

    Returns ``{"root", "frames", "labels", "labels_dropped_out_of_range", "splits": {name:
    n_frames}}``.
    """
    out_frames, world_of = [], {}
    n_labels = n_dropped = 0
    geometry_parts: list[tuple[np.ndarray | None, np.ndarray, float | None]] = []
    label_pairs: list[tuple[np.ndarray, np.ndarray]] = []   # frames that know the true doors
    for df in frames:
        problem = id_problem(df.frame_id)
        if problem is not None:  # would break ImageSets/*.txt or a file name
            raise ValueError(f"frame id {df.frame_id!r} cannot be exported: {problem}; rename "
                             "its scene folder")
        geometry_parts.append((df.surface_offset_m,
                               np.linalg.norm(np.asarray(df.points)[:, :3], axis=1),
                               (df.stats.get("radar") or {}).get("max_range_m")))
        keep = boxes_in_point_cloud_range(df.boxes, label_range_m)
        if df.surface_offset_m is not None:  # a procedural world: its doors are known
            truth = df.gt_boxes[boxes_in_point_cloud_range(df.gt_boxes, label_range_m)]
            label_pairs.append((df.boxes[keep], truth))
        n_labels += int(keep.sum())
        n_dropped += int((~keep).sum())
        points = df.points_with_doppler if with_doppler else df.points
        out_frames.append(Frame(df.frame_id, points, df.boxes[keep],
                                tuple(n for n, k in zip(df.box_labels, keep, strict=True) if k)))
        world_of[df.frame_id] = df.world_id
    worlds = splits or split_groups(sorted(set(world_of.values())), seed)
    by_split = {name: [fid for fid in sorted(world_of) if world_of[fid] in set(ws)]
                for name, ws in worlds.items()}
    root = Path(export_dir)
    write_dataset(root, out_frames, by_split)
    out = {"root": str(root), "frames": len(out_frames), "labels": n_labels,
           "labels_dropped_out_of_range": n_dropped,
           "splits": {k: len(v) for k, v in by_split.items()}, "warnings": []}
    empty = [k for k, v in by_split.items() if not v]
    if not out_frames:
        out["warnings"].append(
            "no frame to export: every world/scene failed or was skipped (the manifest's error "
            "column says why); the folder holds an empty dataset")
    elif empty:
        n_groups = len(set(world_of.values()))
        out["warnings"].append(
            f"split(s) {empty} are empty: {n_groups} world(s)/scene(s) cannot fill train, val "
            "and test (the split is by world); generate more worlds or scenes, or train with "
            "another split")
    for w in out["warnings"]:
        log.warning("%s: %s", root, w)
    write_metadata(root, {
        **(metadata or {}), **out, "geometry": geometry,
        "point_columns": ["x_m", "y_m", "z_m", "intensity_db"] + (
            ["doppler_mps"] if with_doppler else []),
        "label_range_m": None if label_range_m is None else list(label_range_m),
        "worlds": {k: sorted(set(v)) for k, v in worlds.items()},
        "point_geometry": point_geometry(geometry_parts),
        "labels_vs_truth": (label_quality([p for p, _ in label_pairs],
                                          [t for _, t in label_pairs])
                            if label_pairs else None),
        "exported_at": datetime.now(UTC).isoformat(timespec="seconds"),
    })
    return out


def point_geometry(parts: Sequence[tuple[np.ndarray | None, np.ndarray, float | None]]
                   ) -> dict[str, Any] | None:
    """Where an export's points are (``dataset.json["point_geometry"]``, read by the gap
    report): :class:`sim2radar.evaluate.fidelity.FidelityCounts` pooled over the frames that
    know their surface offsets and R_max, from per-frame ``(surface offsets or None, point
    ranges [m], R_max [m] or None)``; None when no frame does (capture folders, measured
    data: no true geometry)."""
    from sim2radar.evaluate.fidelity import FidelityCounts

    known = [(o, r, m) for o, r, m in parts if o is not None and m]
    if not known:
        return None
    max_range = {float(m) for _, _, m in known}
    if len(max_range) > 1:
        raise ValueError(f"frames of one export have different R_max {sorted(max_range)}")
    counts = FidelityCounts.of([o for o, _, _ in known], [r for _, r, _ in known],
                               max_range.pop())
    return {**counts.to_dict(), "frames": len(known),
            "surface": "the world's meshes along each point's ray from the true radar pose"}
