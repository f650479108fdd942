"""Stage 4c: 3D door boxes (``x y z dx dy dz heading``) fitted from door-segment points.

Boxes follow ``vocab.BOX_FIELDS`` and the procedural worlds' convention: in a z-up frame, ``dx``
runs along the wall (the door's width), ``dy`` across it (thickness), ``dz`` is the height and
``heading`` [rad] is the direction of ``dx`` about +z, folded into (−π/2, π/2] (a door box is
symmetric under a half turn).

Fitting (per door): principal axis of the points' ground-plane projection (PCA; for a door
panel this is the wall direction, its normal is the wall normal), extents along it and in z from
robust percentiles, the thickness from the points or ``thickness_m`` when only one face is seen; then the box is
centred half a wall thickness behind the near face of the wall around the door (or
``face_to_center_m`` behind the door face when no wall is seen). When a straight wall is seen
next to the door, its direction sets the heading and only door points within the wall's band
count (frame and closed leaves; an open leaf swung into the room does not): the box is the
**doorway box** of the procedural worlds (frame outline × wall thickness, whatever the leaves'
swing angle). Door
segments that are coplanar and touch along the wall (double-door leaves, a leaf and its frame)
are merged into one box first. Boxes too narrow or too wide for a doorway are dropped at the
end (:func:`plausible_door_boxes`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sim2radar.boxes import DOOR_THICKNESS_M, transform_boxes, wrap_heading
from sim2radar.boxes import box_corners as _box_corners

__all__ = ["DoorFitConfig", "fit_door_box", "fit_door_boxes", "dedupe_boxes",
           "plausible_door_boxes", "transform_boxes", "box_corners"]


@dataclasses.dataclass(frozen=True)
class DoorFitConfig:
    """Options of door-box fitting.

    Attributes
    ----------
    thickness_m : float [m] — box thickness ``dy`` when the doorway's depth is not seen: a
        door box is the doorway box, wall + 2 cm deep (procedural worlds: wall 0.10–0.20 m, so
        0.12–0.22 m; the mean, :data:`sim2radar.boxes.DOOR_THICKNESS_M`, is the default).
    face_to_center_m : float [m] — how far behind the visible door face the box centre lies when
        no wall is seen next to the door.
    wall_search_m : float [m] — wall points within this distance of the door plane (and within
        3× it along the wall) locate the wall's near face.
    merge_gap_m : float [m] — door segments closer than this along the wall (and coplanar within
        ``merge_offset_m``, headings within ``merge_angle_deg``) form one door.
    merge_offset_m : float [m]
    merge_angle_deg : float [deg]
    snap_to_floor_m : float [m] — a box whose bottom is within this of the floor is extended to it.
    min_points : int — door segments with fewer valid points are ignored.
    inlier_m : float [m] — points farther than this from the door's median plane are dropped
        before measuring extents (when at least half the points remain).
    split_gap_m : float [m] — a gap this wide along the wall splits the points; the largest
        run is the door.
    min_top_m : float [m] — with a known floor, a box whose top is lower than this above the
        floor is raised to it (the upper part of a door lost by segmentation; doorways are
        2.06–2.26 m high in the procedural worlds), and a box whose top lies at doorway height
        (``min_top_m`` − 0.25 to + 0.6 above the floor) is extended down to the floor (its lower
        part lost). 0 disables both.
    min_width_m, max_width_m : float [m] — a fitted box narrower or wider than this cannot be
        a door and is dropped (:func:`plausible_door_boxes`): a doorway (leaf + frame) of a
        single door is ~0.7-1.2 m wide, of a double door up to ~2 m (DIN 18101 nominal
        widths: 0.625-1.25 m per leaf; the procedural worlds: 0.92-1.12 m and 1.52-1.92 m);
        narrower boxes are slivers of a door (a jamb, a leaf edge) or a mislabelled object,
        wider ones a door merged with the wall. Chosen from these standards, not from
        reconstruction results. 0 disables each bound.
    """

    thickness_m: float = DOOR_THICKNESS_M
    face_to_center_m: float = 0.0
    wall_search_m: float = 0.35
    merge_gap_m: float = 0.2
    merge_offset_m: float = 0.15
    merge_angle_deg: float = 15.0
    snap_to_floor_m: float = 0.3
    min_points: int = 20
    inlier_m: float = 0.04
    split_gap_m: float = 0.25
    min_top_m: float = 0.0
    min_width_m: float = 0.6
    max_width_m: float = 2.0


def _wrap_half(angle: float | np.ndarray):
    """Fold an angle into (−π/2, π/2] (:func:`sim2radar.boxes.wrap_heading`, with −π/2 taken
    to +π/2)."""
    a = wrap_heading(angle)
    a = np.where(np.isclose(a, -np.pi / 2), np.pi / 2, a)
    return float(a) if np.ndim(a) == 0 else a


def _axes(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    xy = points[:, :2] - points[:, :2].mean(axis=0)
    cov = xy.T @ xy / max(len(xy), 1)
    w, v = np.linalg.eigh(cov)
    a = v[:, 1]
    heading = _wrap_half(math.atan2(a[1], a[0]))
    a = np.array([math.cos(heading), math.sin(heading)])
    n = np.array([-a[1], a[0]])
    return a, n, heading


def _wall_axes(p: np.ndarray, wall_points: np.ndarray | None, config: DoorFitConfig):
    """Axes of the wall the door is set in, from wall points within ``wall_search_m`` (in the
    ground plane) of the door points and within its height: (along, normal, heading, near-face
    offset along the normal) or ``None`` when no straight wall is seen there.

    This makes the box a doorway box whatever the leaves do: an open leaf seen through the
    doorway (perpendicular to the wall) would otherwise set the heading and the extents.
    """
    if wall_points is None or len(wall_points) < 30:
        return None
    from scipy.spatial import cKDTree

    w = np.asarray(wall_points, np.float64)
    w = w[np.isfinite(w).all(axis=1)]
    z0, z1 = np.percentile(p[:, 2], [2, 98])
    w = w[(w[:, 2] > z0) & (w[:, 2] < z1 + 0.3)]
    if len(w) < 30:
        return None
    sub = p[:: max(1, len(p) // 2000)]
    d, _ = cKDTree(sub[:, :2]).query(w[:, :2], distance_upper_bound=config.wall_search_m)
    near = w[np.isfinite(d)]
    if len(near) < 30:
        return None
    for _ in range(2):  # line fit, then refit on its inliers
        a, n, heading = _axes(near)
        t = near[:, :2] @ n
        inl = np.abs(t - np.median(t)) < 0.05
        if inl.mean() < 0.6 or inl.sum() < 30:
            return None
        near = near[inl]
    a, n, heading = _axes(near)
    return a, n, heading, float(np.median(near[:, :2] @ n))


def fit_door_box(points_level: np.ndarray, config: DoorFitConfig = DoorFitConfig(),
                 floor_z_m: float | None = None, pixel_angle_rad: float | None = None,
                 wall_points: np.ndarray | None = None) -> np.ndarray:
    """Fit one door box to its points.

    Parameters
    ----------
    points_level : (N, 3) float — door points in a z-up frame with the camera/sensor at the
        origin (the level frame of :mod:`sim2radar.reconstruct.backproject`) [m].
    floor_z_m : float, optional [m] — floor height in that frame, to snap the bottom to.
    pixel_angle_rad : float, optional [rad] — angular pixel pitch (≈ 1/fx); widens the gap
        that splits the points to three pixel footprints for doors seen at grazing angles.
    wall_points : (M, 3), optional — points of wall segments (same frame); the wall plane next
        to the door fixes the box centre (half a wall thickness behind its near face).

    Returns
    -------
    (7,) float32 — ``x y z dx dy dz heading``.
    """
    p = np.asarray(points_level, dtype=np.float64)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) < 3:
        raise ValueError(f"a door box needs >= 3 points, got {len(p)}")
    wall = _wall_axes(p, wall_points, config)
    wall_face = None
    if wall is not None:
        # doorway box in the wall's axes: keep the door points in the wall's band (frame,
        # closed leaves), drop those beyond it (open leaves swung into the room)
        a, n, heading, wall_face = wall
        t = p[:, :2] @ n
        away = 1.0 if wall_face > 0 else -1.0
        rel = (t - wall_face) * away
        band = (rel > -0.1) & (rel < config.thickness_m + 0.1)
        if band.sum() >= 3:
            p, t = p[band], t[band]
    else:
        a, n, heading = _axes(p)
        t = p[:, :2] @ n
        # keep the door face: points off the dominant vertical plane (jambs, wall pixels at
        # the segment border, seen at grazing angles) would inflate the extents
        face = np.abs(t - np.median(t)) < config.inlier_m
        if face.sum() >= max(3, 0.5 * len(p)):
            p = p[face]
            a, n, heading = _axes(p)
            t = p[:, :2] @ n
    s = p[:, :2] @ a
    # keep the largest run of points along the wall without a gap > split_gap_m (drops stray
    # wall columns that segmentation attached to the door)
    order = np.argsort(s)
    centroid = p.mean(axis=0)
    normal = np.array([n[0], n[1], 0.0])
    rng = float(np.linalg.norm(centroid))
    gap = config.split_gap_m
    if pixel_angle_rad:
        cos_inc = abs(float(normal @ centroid)) / max(rng, 1e-9)
        gap = max(gap, 3.0 * rng * pixel_angle_rad / max(cos_inc, 0.1))
    breaks = np.flatnonzero(np.diff(s[order]) > gap)
    if len(breaks):
        keep = max(np.split(order, breaks + 1), key=len)
        p, s = p[keep], s[keep]
        t = p[:, :2] @ n
    s0, s1 = np.percentile(s, [1, 99])
    t0, t1 = np.percentile(t, [2, 98])
    z0, z1 = np.percentile(p[:, 2], [1, 99])
    if floor_z_m is not None and 0 < z0 - floor_z_m < config.snap_to_floor_m:
        z0 = floor_z_m
    if floor_z_m is not None and z0 - floor_z_m < config.snap_to_floor_m:
        z1 = max(z1, floor_z_m + config.min_top_m)
    if (floor_z_m is not None and config.min_top_m > 0
            and config.min_top_m - 0.25 <= z1 - floor_z_m <= config.min_top_m + 0.6):
        # the top of a door at doorway height: doors stand on the floor, so the bottom
        # (hidden, or split off by segmentation) is the floor
        z0 = min(z0, floor_z_m)
    thick = t1 - t0
    tc = 0.5 * (t0 + t1)
    if wall_face is not None:
        away = 1.0 if wall_face > 0 else -1.0
        tc = wall_face + away * config.thickness_m / 2
        thick = config.thickness_m
    elif thick < config.thickness_m:
        # one face seen: the box spans the wall the door is set in. Centre it half a wall
        # thickness behind the wall's near face when the wall around the door is seen, else
        # ``face_to_center_m`` behind the door face (away from the viewer at t = 0).
        face = float(np.median(t))
        away = 1.0 if face > 0 else -1.0
        tc = face + away * config.face_to_center_m
        if wall_points is not None and len(wall_points):
            w = np.asarray(wall_points, np.float64)
            w = w[np.isfinite(w).all(axis=1)]
            ws, wt = w[:, :2] @ a, w[:, :2] @ n
            near = ((ws > s0 - config.wall_search_m * 3) & (ws < s1 + config.wall_search_m * 3)
                    & (np.abs(wt - face) < config.wall_search_m)
                    & (w[:, 2] > z0) & (w[:, 2] < z1 + 0.5))
            if near.sum() >= 20:
                wall_face = float(np.median(wt[near]))
                if np.mean(np.abs(wt[near] - wall_face) < 0.05) > 0.5:
                    tc = wall_face + away * config.thickness_m / 2
        thick = config.thickness_m
    sc = 0.5 * (s0 + s1)
    cxy = sc * a + tc * n
    return np.array([cxy[0], cxy[1], 0.5 * (z0 + z1), s1 - s0, thick, z1 - z0, heading],
                    dtype=np.float32)


def fit_door_boxes(segment_points: list[np.ndarray], config: DoorFitConfig = DoorFitConfig(),
                   floor_z_m: float | None = None, pixel_angle_rad: float | None = None,
                   wall_points: np.ndarray | None = None) -> tuple[np.ndarray, list[list[int]]]:
    """Group door segments into doors and fit a box to each group.

    Parameters
    ----------
    segment_points : list of (N_k, 3) arrays — points of each door segment, level frame [m].

    Returns
    -------
    boxes : (M, 7) float32; groups : list of lists of input indices, one per box.
    """
    pts = [np.asarray(p, np.float64)[np.isfinite(p).all(axis=1)] for p in segment_points]
    usable = [i for i, p in enumerate(pts) if len(p) >= config.min_points]
    if not usable:
        return np.zeros((0, 7), np.float32), []
    single = {i: fit_door_box(pts[i], config, floor_z_m, pixel_angle_rad) for i in usable}
    parent = {i: i for i in usable}

    def find(i):
        while parent[i] != i:
            i = parent[i]
        return i

    cos_m = math.cos(math.radians(config.merge_angle_deg))
    for ii, i in enumerate(usable):
        for j in usable[ii + 1:]:
            bi, bj = single[i], single[j]
            if abs(math.cos(bi[6] - bj[6])) < cos_m:
                continue
            a = np.array([math.cos(bi[6]), math.sin(bi[6])])
            n = np.array([-a[1], a[0]])
            d = bj[:2] - bi[:2]
            if abs(d @ n) > config.merge_offset_m:
                continue
            gap = abs(d @ a) - 0.5 * (bi[3] + bj[3])
            if gap > config.merge_gap_m:
                continue
            parent[find(j)] = find(i)
    groups: dict[int, list[int]] = {}
    for i in usable:
        groups.setdefault(find(i), []).append(i)
    boxes, out_groups = [], []
    for members in groups.values():
        p = np.concatenate([pts[i] for i in members])
        boxes.append(fit_door_box(p, config, floor_z_m, pixel_angle_rad, wall_points))
        out_groups.append(sorted(members))
    return np.stack(boxes).astype(np.float32), out_groups


def dedupe_boxes(boxes: np.ndarray, max_angle_deg: float = 15.0,
                 max_offset_m: float = 0.3) -> np.ndarray:
    """Drop door boxes that duplicate a wider one: near-parallel (headings within
    ``max_angle_deg``), in the same wall (centres within ``max_offset_m`` across it) and
    overlapping it along the wall. Two fragments of one doorway (e.g. a leaf fit and a
    wall-opening measurement) would otherwise count once as a hit and once as a false alarm.

    Parameters
    ----------
    boxes : (M, 7) ``x y z dx dy dz heading`` [m, rad].

    Returns
    -------
    (K, 7) float32, K <= M, in input order.
    """
    b = np.asarray(boxes, np.float32).reshape(-1, 7)
    keep = np.ones(len(b), bool)
    order = np.argsort(-b[:, 3], kind="stable")  # widest first
    cos_m = math.cos(math.radians(max_angle_deg))
    for ii, i in enumerate(order):
        if not keep[i]:
            continue
        a = np.array([math.cos(b[i, 6]), math.sin(b[i, 6])])
        n = np.array([-a[1], a[0]])
        for j in order[ii + 1:]:
            if not keep[j] or abs(math.cos(float(b[i, 6] - b[j, 6]))) < cos_m:
                continue
            d = b[j, :2] - b[i, :2]
            if abs(d @ n) <= max_offset_m and abs(d @ a) < 0.5 * (b[i, 3] + b[j, 3]):
                keep[j] = False
    return b[keep]


def plausible_door_boxes(boxes: np.ndarray, config: DoorFitConfig = DoorFitConfig()
                         ) -> np.ndarray:
    """The boxes whose width (``dx``) can be a doorway's: within ``[min_width_m,
    max_width_m]`` (a bound of 0 is off).

    Parameters
    ----------
    boxes : (M, 7) ``x y z dx dy dz heading`` [m, rad].

    Returns
    -------
    (K, 7) float32, K <= M, in input order.
    """
    b = np.asarray(boxes, np.float32).reshape(-1, 7)
    keep = np.ones(len(b), bool)
    if config.min_width_m > 0:
        keep &= b[:, 3] >= config.min_width_m
    if config.max_width_m > 0:
        keep &= b[:, 3] <= config.max_width_m
    return b[keep]


def box_corners(box: np.ndarray) -> np.ndarray:
    """Corners of ``x y z dx dy dz heading`` boxes: (8, 3) for one (7,) box, (M, 8, 3) for
    (M, 7) boxes (:func:`sim2radar.boxes.box_corners`, same corner order)."""
    corners = _box_corners(box)
    return corners[0] if np.ndim(box) == 1 else corners
