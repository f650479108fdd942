"""Geometric labels of the ``builtin`` segmenter (step 5 of
:mod:`sim2radar.reconstruct.segment_builtin`).

Each region is labelled from its shape in the level frame (x forward, y left, z up;
:class:`~sim2radar.reconstruct.segment_builtin_geometry.SegmentGeometry`): horizontal up-facing
regions near the lowest level are ``floor``, down-facing ones near the highest ``ceiling``;
vertical ones are labelled by :func:`vertical_label` (door, window, handrail, wall, clutter);
small red regions are ``fire_extinguisher`` (:func:`label_regions`). :func:`door_like` is the
size rule the region merge uses to keep two door-sized rectangles apart.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from sim2radar.reconstruct.segment_builtin_config import SegmentContext, SegmenterConfig
from sim2radar.reconstruct.segment_builtin_geometry import SegmentGeometry, region_geometry

__all__ = ["door_like", "label_regions", "vertical_label"]


def door_like(config: SegmenterConfig, g: SegmentGeometry, floor_z: float | None) -> bool:
    """Door-sized vertical rectangle standing on the floor at ``floor_z`` [m] (before
    labelling)."""
    if floor_z is None or g.vertical_cos > config.thresholds.door_like_max_vertical_cos:
        return False
    return (g.z_min_m < floor_z + config.floor_tolerance_m
            and config.door_height_m[0] <= g.height_m <= config.door_height_m[1]
            and g.width_m <= config.door_width_m[1])


def label_regions(ctx: SegmentContext, regions: np.ndarray, floor_z_known: float | None = None):
    """Label every region of the label map ``regions`` by its geometry (``ctx.points_level``)
    and colour (``ctx.rgb``).

    The floor level is ``floor_z_known`` [m] when the floor plane was measured, else the
    centroid height of the largest up-facing horizontal region (else a low percentile of the
    point heights); the ceiling level likewise from the down-facing regions.

    Returns
    -------
    labels : list[str] — one per region id.
    scores : list[float] — label confidence per region id.
    info : dict — ``floor_z_m`` and ``ceiling_z_m`` [m], the levels the labels used.
    """
    opts, cfg, pl = ctx.config, ctx.thresholds, ctx.points_level
    n = int(regions.max()) + 1
    geos = [region_geometry(pl, regions == i, pixel_angle_rad=ctx.pixel_angle_rad)
            for i in range(n)]
    hsv = cv2.cvtColor(ctx.rgb, cv2.COLOR_RGB2HSV)
    red = (((hsv[..., 0] < cfg.red_hue[0]) | (hsv[..., 0] > cfg.red_hue[1]))
           & (hsv[..., 1] > cfg.red_min_saturation) & (hsv[..., 2] > cfg.red_min_value))
    flat = regions.ravel()
    ok = flat >= 0
    value = np.bincount(flat[ok], hsv[..., 2].ravel()[ok] / 255.0, minlength=n) / np.maximum(
        np.bincount(flat[ok], minlength=n), 1)
    red_frac = np.bincount(flat[ok], red.ravel()[ok], minlength=n) / np.maximum(
        np.bincount(flat[ok], minlength=n), 1)
    cos_h = math.cos(math.radians(cfg.label_tilt_deg))
    sin_v = math.sin(math.radians(cfg.label_tilt_deg))
    # floor and ceiling levels: the largest up-/down-facing horizontal regions
    ups = [g for g in geos if g.vertical_cos > cos_h and g.normal[2] > 0
           and g.centroid[2] < -cfg.floor_below_camera_m]
    downs = [g for g in geos if g.vertical_cos > cos_h and g.normal[2] < 0
             and g.centroid[2] > cfg.ceiling_above_camera_m]
    zs = pl[..., 2][np.isfinite(pl[..., 2])]
    if floor_z_known is not None:
        floor_z = floor_z_known
    elif ups:
        floor_z = max(ups, key=lambda g: g.n_px).centroid[2]
    else:
        floor_z = float(np.percentile(zs, cfg.level_fallback_pct))
    ceil_z = (max(downs, key=lambda g: g.n_px).centroid[2] if downs
              else float(np.percentile(zs, 100 - cfg.level_fallback_pct)))
    tol = opts.floor_tolerance_m
    n_valid = int(np.isfinite(pl[..., 2]).sum())
    labels, scores = [], []
    for i, g in enumerate(geos):
        label, score = "clutter", 0.4
        size = max(g.width_m, g.height_m)
        if (red_frac[i] > cfg.extinguisher_min_red_frac
                and size < cfg.extinguisher_max_size_m):
            label, score = "fire_extinguisher", 0.7
        elif g.vertical_cos > cos_h:
            if g.normal[2] > 0 and g.centroid[2] < floor_z + tol:
                label, score = "floor", 0.9
            elif g.normal[2] < 0 and g.centroid[2] > ceil_z - tol:
                label, score = "ceiling", 0.9
        elif g.vertical_cos < sin_v:
            label, score = vertical_label(opts, g, floor_z, ceil_z, bool(downs), float(value[i]))
        elif g.n_px > cfg.oblique_min_frac * n_valid:
            # a large surface with an oblique fitted normal (depth bent near the image
            # border, where the LiDAR does not reach): the structure it leans towards
            if g.vertical_cos < cfg.oblique_wall_max_cos:
                label, score = "wall", 0.4
            elif g.normal[2] > 0 and g.centroid[2] < 0:
                label, score = "floor", 0.4
            elif g.normal[2] < 0 and g.centroid[2] > 0:
                label, score = "ceiling", 0.4
        labels.append(label)
        scores.append(score)
    info = {"floor_z_m": float(floor_z), "ceiling_z_m": float(ceil_z)}
    return labels, scores, info


def vertical_label(config: SegmenterConfig, g: SegmentGeometry, floor_z: float, ceil_z: float,
                   ceiling_seen: bool, brightness: float = 1.0) -> tuple[str, float]:
    """Label and confidence of a vertical region of geometry ``g``, the floor at ``floor_z`` and
    the ceiling at ``ceil_z`` [m] (``ceiling_seen``: a ceiling region was found, so a door must
    end below it); ``brightness`` is the region's mean HSV value (0–1): glass is bright.

    A door-sized rectangle standing on the floor and ending below the ceiling is a ``door``
    (narrower and shorter ones when cut by the image border, unless cut by the top *and* a
    side border: then neither size is measured); a tall planar fragment near the floor is a
    door fragment (with ``door_partial``); long, thin and at hand height a ``handrail``; a
    wall-set rectangle with a sill a ``window`` (a dark one with a door-height top, the upper
    part of a door); large a ``wall``; else ``clutter``.
    """
    cfg = config.thresholds
    tol = config.floor_tolerance_m
    on_floor = g.z_min_m < floor_z + tol
    below_ceiling = g.z_max_m < ceil_z - cfg.below_ceiling_m or not ceiling_seen
    w_lo, w_hi = config.door_width_m
    h_lo, h_hi = config.door_height_m
    if g.touches_border:  # partly out of view: accept narrower / shorter rectangles
        w_lo, h_lo = cfg.cut_door_min_width_m, h_lo * cfg.cut_door_height_frac
    rel_bottom = g.z_min_m - floor_z
    # cut by the top border and by a side border, neither the height nor the width is
    # seen: a wall close to the camera fills the same corner of the image, so the size
    # rules below have no evidence of a door (the facade search still finds its frame)
    sized = not ("t" in g.borders and ("l" in g.borders or "r" in g.borders))
    if (sized and on_floor and below_ceiling and w_lo <= g.width_m <= w_hi
            and h_lo <= g.height_m <= h_hi and g.fill > cfg.door_min_fill):
        return "door", float(min(0.9, 0.5 + 0.4 * g.fill))
    if (sized and config.door_partial and g.z_min_m < floor_z + cfg.fragment_max_bottom_m
            and below_ceiling and cfg.fragment_min_width_m <= g.width_m <= w_hi
            and cfg.fragment_min_height_m <= g.height_m <= h_hi
            and g.z_max_m - floor_z <= h_hi + cfg.door_top_slack_m
            and g.fill > cfg.fragment_min_fill and g.planarity < cfg.fragment_max_rms_m):
        # a door fragment: LiDAR completion smears the leaf's lower / upper band into the
        # wall or floor; tall, narrow, planar and near the floor (its box is completed to
        # the floor and the doorway height by the door fit)
        return "door", 0.4
    rail = cfg.handrail_bottom_m
    if (g.width_m > cfg.handrail_min_length_m and g.height_m < cfg.handrail_max_height_m
            and rail[0] < rel_bottom < rail[1]):
        return "handrail", 0.6
    sill, win_w, win_h = cfg.window_bottom_m, cfg.window_width_m, cfg.window_height_m
    if (sill[0] < rel_bottom < sill[1] and below_ceiling and win_w[0] <= g.width_m <= win_w[1]
            and win_h[0] <= g.height_m <= win_h[1] and g.fill > cfg.window_min_fill
            and g.planarity < cfg.window_max_rms_m):
        if brightness >= cfg.window_min_brightness:  # glass shows daylight or reflections
            return "window", 0.5
        top = g.z_max_m - floor_z
        if (sized and h_lo <= top <= h_hi + cfg.door_top_slack_m
                and w_lo <= g.width_m <= w_hi):
            # the upper part of a door whose lower part was split off: door-height top
            return "door", 0.4
    if g.height_m > cfg.wall_min_height_m or g.width_m > cfg.wall_min_width_m:
        return "wall", 0.8
    return "clutter", 0.4
