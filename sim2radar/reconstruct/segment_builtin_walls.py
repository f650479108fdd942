"""Wall steps of the ``builtin`` segmenter: wall planes, and what they decide about other regions.

Steps 5 and 6 of :mod:`sim2radar.reconstruct.segment_builtin`, as functions of the call's
:class:`~sim2radar.reconstruct.segment_builtin_config.SegmentContext`: the vertical plane of a
large ``wall`` region (:func:`wall_plane`, :func:`large_walls`, :func:`wall_extents`);
furniture standing proud of a wall becomes ``clutter`` (:func:`proud_of_walls`) and small
pieces lying on a wall's plane become that wall (:func:`flush_with_walls`); pixels that by the
room's geometry can only see the floor or the ceiling in front of every wall join it
(:func:`below_floor`).

A label map is an (H, W) int array of region ids (-1 unlabelled); ``labels`` and ``scores`` are
the label and confidence of each region id. The steps return new maps and lists.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from sim2radar.reconstruct.backproject import column_extent
from sim2radar.reconstruct.segment_builtin_config import SegmentContext
from sim2radar.reconstruct.segment_builtin_geometry import region_geometry
from sim2radar.reconstruct.segment_builtin_labels import vertical_label

__all__ = ["below_floor", "faces_as_wall", "flush_with_walls", "large_walls", "proud_of_walls",
           "wall_extents", "wall_plane"]


def wall_plane(ctx: SegmentContext, mask: np.ndarray):
    """Vertical plane ``nrm · p = d`` of a wall region (``nrm`` horizontal, facing the
    camera, ``d`` the median offset of its points), its geometry and its valid points; None
    when the region is not vertical, lies within ``wall_min_distance_m`` of the camera, or
    has fewer than ``wall_min_points`` pixels with depth (a region grown over pixels the
    LiDAR missed)."""
    cfg, pl = ctx.thresholds, ctx.points_level
    wp = pl[mask & ctx.valid]
    if len(wp) < cfg.wall_min_points:
        return None
    g = region_geometry(pl, mask, pixel_angle_rad=ctx.pixel_angle_rad)
    if g.vertical_cos > cfg.wall_max_vertical_cos:
        return None
    nrm = np.array([g.normal[0], g.normal[1], 0.0])
    nrm /= np.linalg.norm(nrm)
    d = float(np.median(wp @ nrm))
    return None if d > -cfg.wall_min_distance_m else (nrm, d, g, wp)


def large_walls(ctx: SegmentContext, regions: np.ndarray, labels, min_frac: float, top: int):
    """``(region id, (nrm, d, geometry, points))`` of the ``wall`` regions among the
    ``top`` largest regions that hold at least ``min_frac`` of the valid pixels and have a
    vertical plane (:func:`wall_plane`), largest first."""
    n_valid = int(ctx.valid.sum())
    counts = np.bincount(regions[regions >= 0], minlength=len(labels))
    out = []
    for wi in np.argsort(-counts)[:top]:
        if labels[wi] != "wall" or counts[wi] < min_frac * n_valid:
            continue
        plane = wall_plane(ctx, regions == wi)
        if plane is not None:
            out.append((int(wi), plane))
    return out


def wall_extents(ctx: SegmentContext, regions: np.ndarray, labels, min_frac: float,
                 top: int):
    """``(region id, nrm, d, along, (s0, s1))`` of :func:`large_walls`: the horizontal
    along-wall axis and the extent of the wall's points along it (percentiles
    ``wall_extent_pct``, 100 − that) [m]."""
    pct = [ctx.thresholds.wall_extent_pct, 100 - ctx.thresholds.wall_extent_pct]
    out = []
    for wi, (nrm, d, _, wp) in large_walls(ctx, regions, labels, min_frac, top):
        along = np.array([-nrm[1], nrm[0], 0.0])
        s0, s1 = np.percentile(wp @ along, pct)
        out.append((wi, nrm, d, along, (float(s0), float(s1))))
    return out


def proud_of_walls(ctx: SegmentContext, regions: np.ndarray, labels, scores):
    """Furniture standing against a wall: vertical regions ``proud_m`` in front of a large
    wall plane become ``clutter``.

    A door leaf is flush with its wall or set into it, and a window is set into it; a cabinet
    or a radiator stands 0.1–0.6 m in front of it. A door/wall/window region of fewer
    pixels than the wall (a large furniture front may itself count among the walls), with
    at least 80 % of its points within the wall's extent, whose median distance in front of
    the plane is within ``proud_m`` and whose 10th percentile is more than 3 cm, is that
    furniture — unless its top is at door height and its plane is turned from the wall's
    (an open leaf swung out of its doorway stands proud too, up to the lintel, but turned
    by its swing angle; a tall cabinet's front faces as the wall does), or it reaches
    above any door or its top is cut by the image (a wall of its own). With
    ``proud_split``, pixels of a large wall region itself that stand proud of its plane
    (furniture or an open leaf that the depth completion blended into the wall) are split
    off as their own regions, of at least 0.2 % of the image: ``door`` when door-sized up
    to door height and turned from the wall, ``clutter`` otherwise. Heights are measured
    from ``ctx.floor_z_m``.

    Returns
    -------
    regions, labels, scores, proud : the label map and lists, and the set of region ids turned
        to clutter (the door growing step skips them).
    """
    opts, cfg, pl, floor_z = ctx.config, ctx.thresholds, ctx.points_level, ctx.floor_z_m
    lo, hi = opts.proud_m
    valid = ctx.valid
    counts = np.bincount(regions[regions >= 0], minlength=len(labels))
    walls = wall_extents(ctx, regions, labels, cfg.wall_min_frac, cfg.wall_top_n)
    labels, scores = list(labels), list(scores)
    proud: set[int] = set()
    if opts.proud_split:
        # furniture merged into its wall's region (a completion that blends the two):
        # connected pixels of the wall region standing proud of its plane
        h, w = regions.shape
        regions = regions.copy()
        for wi, nrm, d, _, _ in walls:
            with np.errstate(invalid="ignore"):
                front = pl @ nrm - d
            blob = (regions == wi) & valid & (front > lo) & (front < hi)
            blob = cv2.morphologyEx(blob.astype(np.uint8), cv2.MORPH_OPEN,
                                    np.ones((cfg.proud_open_px,) * 2, np.uint8))
            n_cc, cc, stats, _ = cv2.connectedComponentsWithStats(blob, connectivity=4)
            for c in range(1, n_cc):
                if stats[c, cv2.CC_STAT_AREA] < cfg.proud_split_min_frac * h * w:
                    continue
                blob_c = cc == c
                regions[blob_c] = len(labels)
                g = region_geometry(pl, blob_c, pixel_angle_rad=ctx.pixel_angle_rad)
                top = np.percentile(pl[..., 2][blob_c], cfg.proud_top_pct) - floor_z
                if (top >= opts.door_height_m[0]
                        and not faces_as_wall(g.normal, nrm, cfg.parallel_deg)):
                    # up to door height and turned from the wall: an open leaf swung out of
                    # its doorway when it is door-sized; either way no longer part of the
                    # wall's plane
                    label, score = vertical_label(opts, g, floor_z, np.inf, False)
                    labels.append("door" if label == "door" else "clutter")
                    scores.append(score if label == "door" else 0.4)
                    continue
                proud.add(len(labels))
                labels.append("clutter")
                scores.append(0.5)
        counts = np.bincount(regions[regions >= 0], minlength=len(labels))
    for i, lbl in enumerate(labels):
        if lbl not in ("door", "wall", "window") or counts[i] < cfg.proud_min_px:
            continue
        pts = pl[(regions == i) & valid]
        if len(pts) < cfg.proud_min_points:
            continue
        top = np.percentile(pts[:, 2], cfg.proud_top_pct) - floor_z
        tall = top >= opts.door_height_m[0]
        if tall and (top > opts.door_height_m[1] or (regions[0] == i).any()):
            continue  # up to the ceiling, or its top not seen: a wall
        normal = region_geometry(pl, regions == i).normal if tall else None
        for wi, nrm, d, along, (s0, s1) in walls:
            if counts[i] >= counts[wi] or (
                    tall and not faces_as_wall(normal, nrm, cfg.parallel_deg)):
                continue
            sa = pts @ along
            margin = cfg.proud_extent_margin_m
            if ((sa > s0 - margin) & (sa < s1 + margin)).mean() < cfg.proud_within_frac:
                continue
            f10, f50 = np.percentile(pts @ nrm - d, [cfg.proud_front_pct, 50])
            if lo <= f50 <= hi and f10 > cfg.proud_min_front_m:
                labels[i], scores[i] = "clutter", 0.5
                proud.add(i)
                break
    return regions, labels, scores, proud


def flush_with_walls(ctx: SegmentContext, regions: np.ndarray, labels, skip=frozenset()):
    """Wall pieces too small for a wall by size — the strips a handrail, a window or a
    shadow cut out of a wall, below the size the vertical rule calls ``wall`` — are
    ``clutter`` only if they stand apart from the walls: a vertical region whose points lie
    on a large wall's plane (80 % within ``flush_tol_m`` + 1 % of their range) and within
    its extent is that wall (furniture stands proud of it, :func:`proud_of_walls`)."""
    cfg, pl = ctx.thresholds, ctx.points_level
    labels = list(labels)
    valid = ctx.valid
    walls = wall_extents(ctx, regions, labels, cfg.wall_min_frac, cfg.wall_top_n)
    if not walls:
        return labels
    for i, lbl in enumerate(labels):
        if lbl != "clutter" or i in skip:
            continue
        m = (regions == i) & valid
        if m.sum() < cfg.flush_min_px:
            continue
        pts = pl[m]
        g = region_geometry(pl, m, pixel_angle_rad=ctx.pixel_angle_rad)
        if g.vertical_cos > cfg.flush_max_vertical_cos:
            continue
        tol = cfg.flush_tol_m + cfg.flush_tol_per_m * np.linalg.norm(pts, axis=1)
        margin = cfg.flush_extent_margin_m
        for _, nrm, d, along, (s0, s1) in walls:
            sa = pts @ along
            on = (np.abs(pts @ nrm - d) < tol) & (sa > s0 - margin) & (sa < s1 + margin)
            if on.mean() >= cfg.flush_on_frac:
                labels[i] = "wall"
                break
    return labels


def faces_as_wall(normal: np.ndarray, wall_normal: np.ndarray, max_deg: float) -> bool:
    """The region's plane faces the same way as the wall's (within ``max_deg``): standing
    proud of the wall, it is a cabinet's front, not a door leaf swung out of its doorway
    (turned by the swing angle; a leaf swung against the wall is only its thickness proud)."""
    return abs(float(normal[:2] @ wall_normal[:2])) / max(
        float(np.linalg.norm(normal[:2])), 1e-9) > math.cos(math.radians(max_deg))


def below_floor(ctx: SegmentContext, regions: np.ndarray, labels, scores, rays: np.ndarray):
    """Pixels that can only be floor (ceiling) by the room's geometry join the floor
    (ceiling) region.

    * A measured point more than ``below_floor_m`` (+ 1 % of its range) below the floor
      level (above the ceiling) is impossible in a room: the depth there was extrapolated
      from a wall (LiDAR completion fills the band under the lowest beam from the nearest
      beams), and the pixel sees the floor (ceiling) in front of that wall.
    * With ``fill_no_depth``, a pixel without depth below the lowest (above the highest)
      measured pixel of its column whose viewing ray points down (up) sees the floor
      (ceiling).

    Either way the ray must cross the floor (ceiling) plane in front of every large wall
    plane; otherwise it sees that wall. ``rays`` (H, W, 3) are the level-frame viewing
    directions (camera z = 1); the levels are ``ctx.floor_z_m`` and ``ctx.ceiling_z_m``.
    """
    opts, cfg, pl = ctx.config, ctx.thresholds, ctx.points_level
    floor_z, ceil_z = ctx.floor_z_m, ctx.ceiling_z_m
    valid = ctx.valid
    h = valid.shape[0]
    rng = np.linalg.norm(np.where(valid[..., None], pl, 0), axis=-1)
    tol = opts.below_floor_m + cfg.below_floor_per_m * rng
    with np.errstate(invalid="ignore"):
        floor_px = valid & (pl[..., 2] < floor_z - tol)
        ceil_px = valid & (pl[..., 2] > ceil_z + tol)
    rows = np.arange(h)[:, None]
    first, last = column_extent(valid)
    if opts.fill_no_depth:
        floor_px |= ~valid & (rows > last[None, :]) & (rays[..., 2] < -cfg.fill_ray_slope)
        ceil_px |= ~valid & (rows < first[None, :]) & (rays[..., 2] > cfg.fill_ray_slope)
    # the ray must reach the floor (ceiling) plane in front of every large wall plane:
    # otherwise the pixel sees the wall's lower (upper) part
    walls = large_walls(ctx, regions, labels, cfg.floor_wall_min_frac, cfg.floor_wall_top_n)
    for px, level in ((floor_px, floor_z), (ceil_px, ceil_z)):
        with np.errstate(invalid="ignore", divide="ignore"):
            t = level / rays[..., 2]
        q = rays * t[..., None]
        for _, (nrm, d, _, _) in walls:
            with np.errstate(invalid="ignore"):
                px &= ~(q @ nrm < d - cfg.floor_wall_margin_m)
    labels, scores = list(labels), list(scores)
    regions = regions.copy()
    for px, name in ((floor_px, "floor"), (ceil_px, "ceiling")):
        if px.sum() < cfg.min_segment_px:
            continue
        ids = [i for i, lab in enumerate(labels) if lab == name]
        if ids:
            cnt = np.bincount(regions[regions >= 0], minlength=len(labels))
            target = max(ids, key=lambda i: cnt[i])
        else:
            target = len(labels)
            labels.append(name)
            scores.append(0.6)
        regions[px] = target
    return regions, labels, scores
