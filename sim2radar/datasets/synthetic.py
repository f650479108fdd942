"""Synthetic door frames for tests, benchmarks and smoke runs (not a radar simulation).

Each frame is a corridor seen by a radar at the origin (x forward, y left, z up, mounted
``radar_height_m`` above the floor): two noisy wall lines, 1-3 doors set into the walls,
floor returns and uniform clutter, ``points_per_frame`` points in all with an intensity column.
Doors are denser and brighter than walls, as metal doors are in real 77 GHz data, so a detector
can learn them in a few hundred steps. Door sizes follow the statistics documented in
:mod:`sim2radar.detect.config` (0.85-1.0 m wide, 0.12-0.3 m deep, 2.0-2.1 m tall).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim2radar.boxes import points_in_boxes
from sim2radar.datasets.openpcdet import Frame, OpenPCDetDataset, write_dataset, write_metadata

__all__ = ["SYNTHETIC_DOMAIN", "make_door_frames", "write_synthetic_dataset"]

#: ``domain`` that ``sim2radar detect-demo-data`` declares in its ``dataset.json``: these
#: frames are neither measured nor simulated radar, and a sweep must not call them either
SYNTHETIC_DOMAIN = "synthetic (detect-demo-data)"


def _door_points(rng, box: np.ndarray, n: int) -> np.ndarray:
    """Points on a door: mostly on the leaf plane, some on the frame edges."""
    x, y, z, dx, dy, dz, h = box
    u = rng.uniform(-0.5, 0.5, n) * dx
    v = rng.normal(0.0, dy / 6, n).clip(-dy / 2, dy / 2)
    w = rng.uniform(-0.5, 0.5, n) * dz
    edge = rng.random(n) < 0.35  # jambs
    u[edge] = np.sign(u[edge]) * dx / 2 * rng.uniform(0.85, 1.0, edge.sum())
    c, s = np.cos(h), np.sin(h)
    return np.column_stack([x + u * c - v * s, y + u * s + v * c, z + w])


def make_door_frames(
    n_frames: int,
    seed: int = 0,
    points_per_frame: int = 2000,
    num_point_features: int = 4,
    radar_height_m: float = 1.05,
    first_id: int = 0,
) -> list[Frame]:
    """Generate corridor frames with labelled doors.

    Parameters
    ----------
    n_frames : number of frames.
    seed : one seed -> the same frames on every run.
    points_per_frame : points per frame (IFR averages ~2,057).
    num_point_features : columns per point: x, y, z [m], intensity in [0, 1], then zeros.
    radar_height_m : radar height above the floor [m] (floor at z = -radar_height_m).
    first_id : frame ids are ``f"{first_id + i:06d}"``.

    Returns
    -------
    list of :class:`~sim2radar.datasets.openpcdet.Frame` with ``door`` boxes.
    """
    if points_per_frame < 100:
        raise ValueError(f"points_per_frame must be >= 100, got {points_per_frame}")
    if num_point_features < 4:
        raise ValueError("num_point_features must be >= 4 (x, y, z, intensity)")
    rng = np.random.default_rng(seed)
    floor = -radar_height_m
    frames = []
    for i in range(n_frames):
        yaw = rng.uniform(-0.4, 0.4)
        half_w = rng.uniform(1.0, 1.7)
        c, s = np.cos(yaw), np.sin(yaw)

        def to_radar(a, lat, c=c, s=s):
            return a * c - lat * s, a * s + lat * c

        n_doors = int(rng.integers(1, 4))
        # three slots along the corridor, 1.5 m apart, jittered: doors never overlap
        slots = np.sort(rng.choice(3, size=n_doors, replace=False))
        along = 0.8 + 1.5 * slots + rng.uniform(0.0, 0.45, n_doors)
        boxes = []
        for a in along:
            side = rng.choice([-1.0, 1.0])
            dx, dy, dz = rng.uniform(0.85, 1.0), rng.uniform(0.12, 0.3), rng.uniform(2.0, 2.1)
            bx, by = to_radar(a, side * half_w)
            boxes.append([bx, by, floor + dz / 2, dx, dy, dz, yaw])
        boxes = np.asarray(boxes)

        parts, intens = [], []
        # 3.5-7 % of the frame's points per door (70-140 of 2,000), at least 8
        n_door_pts = np.maximum(8, (rng.uniform(0.035, 0.07, n_doors) * points_per_frame)
                                .astype(int))
        for box, n in zip(boxes, n_door_pts, strict=True):
            parts.append(_door_points(rng, box, int(n)))
            intens.append(rng.normal(0.8, 0.08, int(n)))
        n_rest = points_per_frame - int(n_door_pts.sum())
        n_wall, n_floor = int(0.6 * n_rest), int(0.15 * n_rest)
        a = rng.uniform(-0.5, 6.5, n_wall)
        lat = rng.choice([-half_w, half_w], n_wall) + rng.normal(0, 0.03, n_wall)
        wx, wy = to_radar(a, lat)
        wall = np.column_stack([wx, wy, rng.uniform(floor, floor + 2.6, n_wall)])
        wall = wall[~points_in_boxes(wall, boxes).any(axis=1)]
        parts.append(wall)
        intens.append(rng.normal(0.3, 0.08, len(wall)))
        fa, fl = rng.uniform(0.3, 6.0, n_floor), rng.uniform(-half_w, half_w, n_floor)
        fx, fy = to_radar(fa, fl)
        parts.append(np.column_stack([fx, fy, floor + rng.normal(0, 0.02, n_floor)]))
        intens.append(rng.normal(0.15, 0.05, n_floor))
        n_clutter = points_per_frame - sum(len(p) for p in parts)  # wall holes refill here
        parts.append(rng.uniform([-1.0, -5.2, floor], [5.4, 5.2, 2.0], (n_clutter, 3)))
        intens.append(rng.uniform(0.0, 0.6, n_clutter))
        xyz = np.vstack(parts)
        inten = np.clip(np.concatenate(intens), 0.0, 1.0)
        pts = np.zeros((len(xyz), num_point_features), dtype=np.float32)
        pts[:, :3], pts[:, 3] = xyz, inten
        pts = pts[rng.permutation(len(pts))]
        frames.append(Frame(f"{first_id + i:06d}", pts, boxes.astype(np.float32),
                            ("door",) * len(boxes)))
    return frames


def write_synthetic_dataset(
    root: str | Path,
    n_train: int = 32,
    n_val: int = 8,
    n_test: int = 16,
    seed: int = 0,
    points_per_frame: int = 2000,
    num_point_features: int = 4,
    domain: str = SYNTHETIC_DOMAIN,
) -> OpenPCDetDataset:
    """Write a synthetic door dataset in OpenPCDet's layout with train/val/test splits, and a
    ``dataset.json`` that declares its ``domain`` (default :data:`SYNTHETIC_DOMAIN`), the
    generator and its settings (so a sweep or gap report reads the frames as what they are,
    not as measured radar)."""
    n = n_train + n_val + n_test
    frames = make_door_frames(n, seed=seed, points_per_frame=points_per_frame,
                              num_point_features=num_point_features)
    ids = [f.frame_id for f in frames]
    splits = {"train": ids[:n_train], "val": ids[n_train:n_train + n_val],
              "test": ids[n_train + n_val:]}
    ds = write_dataset(root, frames, splits)
    write_metadata(root, {
        "domain": domain,
        "generator": "sim2radar.datasets.synthetic.make_door_frames (corridor walls + doors; "
                     "not a radar simulation)",
        "seed": int(seed), "points_per_frame": int(points_per_frame),
        "num_point_features": int(num_point_features),
        "splits": {name: len(v) for name, v in splits.items()},
    })
    return ds
