"""Door steps of the ``builtin`` segmenter: door leaves, wall openings and door frames.

Steps 5, 7 and 8 of :mod:`sim2radar.reconstruct.segment_builtin`, as functions of the call's
:class:`~sim2radar.reconstruct.segment_builtin_config.SegmentContext`: door leaves completed
from their lower fragment by colour (:func:`grow_doors`); doors and windows seen through a
rectangle of a wall plane, with their doorway boxes (:func:`wall_openings`); doorways found by
their frames on the rectified wall planes (:func:`wall_planes`, :func:`facade_doors`, with
:mod:`sim2radar.reconstruct.facade`). The openings and frames are searched on the wall planes of
:mod:`~sim2radar.reconstruct.segment_builtin_walls`.

A label map is an (H, W) int array of region ids (-1 unlabelled); ``labels`` and ``scores`` are
the label and confidence of each region id. The steps return new maps and lists.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from sim2radar.boxes import wrap_heading
from sim2radar.reconstruct.facade import WallPlane, find_facade_doors
from sim2radar.reconstruct.segment_builtin_config import SegmentContext
from sim2radar.reconstruct.segment_builtin_geometry import region_geometry
from sim2radar.reconstruct.segment_builtin_walls import wall_extents, wall_plane

__all__ = ["facade_doors", "grow_doors", "wall_openings", "wall_planes"]


def grow_doors(ctx: SegmentContext, regions: np.ndarray, labels, scores, skip=frozenset()):
    """Complete door leaves from their lower fragment by colour.

    LiDAR-completed depth blurs a leaf into its wall, so often only the leaf's lower part
    survives as a region (labelled clutter or a small wall) and its upper part joins the
    wall. For each vertical fragment standing on the floor (bottom within
    ``door_bottom_max_m``) whose mean colour differs from its wall's (ΔE > ``grow_colour``),
    the pixels within its image columns that are connected to it and of its colour
    (ΔE < ``grow_colour``) are taken; if that grown region is a door (door width, top at
    door height, below the ceiling) it becomes a ``door`` region. Region ids in ``skip`` (the
    furniture :func:`~sim2radar.reconstruct.segment_builtin_walls.proud_of_walls` found) are not
    grown; colours are ``ctx.lab``, heights from ``ctx.floor_z_m`` up to ``ctx.ceiling_z_m``.

    Returns
    -------
    regions, labels, scores : the label map and lists, grown leaves relabelled ``door``.
    """
    opts, cfg, pl, lab = ctx.config, ctx.thresholds, ctx.points_level, ctx.lab
    floor_z, ceil_z = ctx.floor_z_m, ctx.ceiling_z_m
    n = len(labels)
    flat = regions.ravel()
    ok = flat >= 0
    cnt = np.bincount(flat[ok], minlength=n).astype(np.float64)
    n_valid = int(np.isfinite(pl[..., 2]).sum())
    col = np.stack([np.bincount(flat[ok], lab[..., c].ravel()[ok], minlength=n)
                    for c in range(3)], 1) / np.maximum(cnt, 1)[:, None]
    big_wall = np.array([lbl == "wall" and cnt[i] >= cfg.wall_min_frac * n_valid
                         for i, lbl in enumerate(labels)], bool)
    labels, scores = list(labels), list(scores)
    regions = regions.copy()
    h, w = regions.shape
    taken = np.zeros((h, w), bool)
    for i in np.argsort(-cnt):
        i = int(i)
        if (cnt[i] < cfg.grow_min_px or labels[i] not in ("clutter", "wall", "window")
                or big_wall[i]
                or i in skip):
            continue
        mask = regions == i
        if (mask & taken).any():
            continue
        g = region_geometry(pl, mask, max_points=cfg.quick_fit_points,
                            pixel_angle_rad=ctx.pixel_angle_rad)
        if (g.vertical_cos > cfg.grow_max_vertical_cos
                or g.z_min_m > floor_z + opts.door_bottom_max_m
                or g.width_m > opts.door_width_m[1]):
            continue
        ys, xs = np.nonzero(mask)
        x0, x1 = xs.min(), xs.max() + 1
        close = np.linalg.norm(lab - col[i], axis=-1) < opts.grow_colour
        allowed = np.zeros((h, w), bool)
        allowed[:, x0:x1] = True
        grow = close & allowed & (regions >= 0) & ~taken
        grow &= np.isin(regions, np.flatnonzero(
            [labels[j] in ("wall", "clutter", "window", "door") for j in range(n)]))
        grow |= mask
        ncc, cc = cv2.connectedComponents(grow.astype(np.uint8), connectivity=4)
        ids = np.unique(cc[mask])
        grown = np.isin(cc, ids[ids > 0])
        # the wall the grown pixels came from must differ in colour from the leaf
        donors = np.unique(regions[grown & ~mask])
        if any(big_wall[j] and np.linalg.norm(col[j] - col[i]) < opts.grow_colour
               for j in donors):
            continue
        gg = region_geometry(pl, grown, pixel_angle_rad=ctx.pixel_angle_rad)
        top = gg.z_max_m - floor_z
        slack = cfg.door_top_slack_m
        if (gg.vertical_cos < cfg.grow_max_vertical_cos
                and gg.z_min_m < floor_z + opts.door_bottom_max_m
                and opts.door_height_m[0] - slack <= top <= opts.door_height_m[1] + slack
                and opts.door_width_m[0] <= gg.width_m <= opts.door_width_m[1]
                and gg.z_max_m < ceil_z - cfg.below_ceiling_m):
            regions[grown] = i
            labels[i] = "door"
            scores[i] = 0.5
            taken |= grown
    return regions, labels, scores


def wall_openings(ctx: SegmentContext, regions: np.ndarray, labels, scores):
    """Doors and windows set into walls: pixels seen *behind* a wall plane through a
    rectangle of the wall (a recessed leaf, a window pane, or a room through an open door).

    For each large wall region, every other pixel whose point lies 4 cm – 4 m behind the
    wall plane and whose viewing ray crosses the plane inside the wall's extent is a
    candidate; connected candidates form an opening, measured on the wall plane (width
    along the wall, bottom and top height), when the wall frames it left and right (the
    wall region, or another large wall region on its plane: a doorway may split its wall
    in two). Door-sized openings standing on the floor become door boxes (spanning the
    wall: ``door_thickness_m`` behind the wall face) and their recessed pixels (< 0.35 m
    behind) a ``door`` segment; sill-height openings a ``window``.

    Returns the updated regions, labels, scores and a list of door boxes (level frame,
    ``x y z dx dy dz heading``).
    """
    opts, cfg, pl = ctx.config, ctx.thresholds, ctx.points_level
    floor_z, ceil_z = ctx.floor_z_m, ctx.ceiling_z_m
    h, w = regions.shape
    valid = ctx.valid
    n_reg = int(regions.max()) + 1
    counts = np.bincount(regions[regions >= 0], minlength=n_reg)
    walls = [i for i in np.argsort(-counts) if labels[i] == "wall"
             and counts[i] > cfg.opening_wall_min_frac * valid.sum()]
    boxes: list[list[float]] = []
    used = np.zeros((h, w), bool)
    labels, scores = list(labels), list(scores)
    is_wall = np.isin(regions, walls)
    for wi in walls[:cfg.opening_max_walls]:
        mask = regions == wi
        plane = wall_plane(ctx, mask)
        if plane is None:
            continue
        nrm, d, g, wp = plane
        along = np.array([-nrm[1], nrm[0], 0.0])
        s_w = wp @ along
        s0, s1 = np.percentile(s_w, [cfg.opening_wall_extent_pct,
                                     100 - cfg.opening_wall_extent_pct])
        npd = pl @ nrm
        with np.errstate(invalid="ignore", divide="ignore"):
            behind = d - npd  # > 0 behind the wall
            q = pl * (d / npd)[..., None]  # ray crossing with the wall plane
        sq, zq = q @ along, q[..., 2]
        # (pixels of the wall region itself count too: a recessed leaf of a similar colour
        # may have been merged into the wall)
        inset = cfg.opening_inset_m
        cand = (valid & ~used & (behind > cfg.opening_plane_tol_m)
                & (behind < cfg.opening_max_behind_m)
                & (sq > s0 + inset) & (sq < s1 - inset)
                & (zq > floor_z - cfg.opening_below_floor_m)
                & (zq < g.z_max_m + cfg.opening_above_wall_m))
        cand = cv2.morphologyEx(cand.astype(np.uint8), cv2.MORPH_OPEN,
                                np.ones((cfg.opening_open_px,) * 2, np.uint8))
        n_cc, cc, stats, _ = cv2.connectedComponentsWithStats(cand, connectivity=8)
        for c in range(1, n_cc):
            if stats[c, cv2.CC_STAT_AREA] < max(cfg.opening_min_px,
                                                cfg.opening_min_frac * h * w):
                continue
            m = cc == c
            # the opening must be framed by this wall left and right of it: pixels of the
            # wall region at its middle row, or of another wall region on the same plane at
            # its quarter, middle and three-quarter rows (the wall beyond a door may be a
            # region of its own)
            x0, x1 = stats[c, cv2.CC_STAT_LEFT], stats[c, cv2.CC_STAT_LEFT] + stats[c, cv2.CC_STAT_WIDTH]
            rows = np.flatnonzero(m.any(axis=1))
            mid = rows[len(rows) // 2]
            quart = rows[[len(rows) // 4, len(rows) // 2, 3 * len(rows) // 4]]
            coplanar = is_wall[quart] & (np.abs(behind[quart]) < cfg.opening_plane_tol_m)
            fp = cfg.opening_frame_px
            left_wall = (mask[mid, max(0, x0 - fp):x0].any() or x0 == 0
                         or coplanar[:, max(0, x0 - fp):x0].any(1).all())
            right_wall = (mask[mid, x1:min(w, x1 + fp)].any() or x1 == w
                          or coplanar[:, x1:min(w, x1 + fp)].any(1).all())
            if not (left_wall and right_wall):
                continue
            ss, zz = sq[m], zq[m]
            pct = [cfg.opening_extent_pct, 100 - cfg.opening_extent_pct]
            a0, a1 = np.percentile(ss, pct)
            b0, b1 = np.percentile(zz, pct)
            width, bottom, top = a1 - a0, b0 - floor_z, b1 - floor_z
            recess = m & (behind < cfg.recess_max_m)
            kind = None
            # doors stand on the floor, windows have a sill (>= 0.8 m in the procedural
            # worlds); LiDAR-completed depth often loses an opening's lowest band, so a
            # door-height opening whose bottom is below ``door_bottom_max_m`` is a door
            slack = cfg.door_top_slack_m
            sill, win_w, win_h = (cfg.opening_window_bottom_m, cfg.window_width_m,
                                  cfg.opening_window_height_m)
            if (bottom < opts.door_bottom_max_m
                    and opts.door_width_m[0] <= width
                    <= opts.door_width_m[1] + cfg.opening_door_width_slack_m
                    and opts.door_height_m[0] - slack <= top <= opts.door_height_m[1] + slack
                    and b1 < ceil_z - cfg.below_ceiling_m):
                kind = "door"
            elif (max(sill[0], opts.door_bottom_max_m) < bottom < sill[1]
                  and win_w[0] <= width <= win_w[1] and win_h[0] <= b1 - b0 <= win_h[1]):
                kind = "window"
            if kind is None:
                continue
            used |= m
            if recess.sum() >= cfg.min_segment_px:
                regions = regions.copy()
                regions[recess] = len(labels)
                labels.append(kind)
                scores.append(0.7)
            if kind == "door":
                th = opts.door_thickness_m
                cxy = 0.5 * (a0 + a1) * along[:2] + (d - th / 2) * nrm[:2]
                heading = wrap_heading(math.atan2(along[1], along[0]))
                boxes.append([float(cxy[0]), float(cxy[1]), float(floor_z + top / 2),
                              float(width), th, float(top), float(heading)])
    return regions, labels, scores, boxes


def wall_planes(ctx: SegmentContext, regions: np.ndarray, labels) -> list[WallPlane]:
    """Planes of the large vertical ``wall`` regions (coplanar ones merged), with the
    along-wall extent of their pixels widened by ``facade_wall_pad_m`` (a door may split
    its wall).

    Regions within ``facade_coplanar_deg`` and ``facade_coplanar_m`` of each other are one
    wall; its face is the front-most of them
    (the largest offset: normals face the camera). A closed leaf is recessed a few
    centimetres behind its wall's face and a double door's leaves can outnumber the wall
    pixels around them: on the leaves' plane the frame around them lies in front of it
    (occluded cells) and the facade search would not see its posts."""
    cfg = ctx.thresholds
    pad = cfg.facade_wall_pad_m
    cos_c = math.cos(math.radians(cfg.facade_coplanar_deg))
    planes: list[WallPlane] = []
    for _, nrm, d, _, (s0, s1) in wall_extents(ctx, regions, labels, cfg.facade_wall_min_frac,
                                               cfg.facade_wall_top_n):
        for j, q in enumerate(planes):
            if q.normal @ nrm > cos_c and abs(q.offset_m - d) < cfg.facade_coplanar_m:
                lo, hi = q.s_range_m
                planes[j] = WallPlane(q.normal, max(q.offset_m, d),
                                      (min(lo, s0 - pad), max(hi, s1 + pad)))
                break
        else:
            planes.append(WallPlane(nrm, d, (s0 - pad, s1 + pad)))
    return planes


def facade_doors(ctx: SegmentContext, regions: np.ndarray, labels, scores):
    """Doorways found by their frames on the rectified wall planes
    (:mod:`sim2radar.reconstruct.facade`, options ``ctx.config.facade_config``, on the planes
    of :func:`wall_planes`); their pixels among wall, clutter, window and door regions become
    ``door`` segments.

    Returns
    -------
    regions, labels, scores : the label map and lists with the doorways' segments added.
    boxes : list of [x, y, z, dx, dy, dz, heading] — the doorway boxes (level frame) [m, rad].
    """
    sigma = ctx.thresholds.facade_blur_sigma_px
    lab = cv2.cvtColor(cv2.GaussianBlur(ctx.rgb, (0, 0), sigma).astype(np.float32) / 255.0,
                       cv2.COLOR_RGB2LAB)[..., 0]
    grad = (cv2.Sobel(lab, cv2.CV_32F, 1, 0, ksize=3) / 8.0,
            cv2.Sobel(lab, cv2.CV_32F, 0, 1, ksize=3) / 8.0)
    boxes: list[list[float]] = []
    labels, scores = list(labels), list(scores)
    regions = regions.copy()
    for plane in wall_planes(ctx, regions, labels):
        for door in find_facade_doors(plane, ctx.floor_z_m, ctx.ceiling_z_m, ctx.rotation,
                                      ctx.intrinsics, ctx.points_level, grad,
                                      ctx.config.facade_config):
            boxes.append([float(x) for x in door.box_level])
            m = door.mask & (regions >= 0)
            keep = np.isin(regions, [i for i, lbl in enumerate(labels)
                                     if lbl in ("wall", "clutter", "window", "door")])
            m &= keep
            if m.sum() >= ctx.thresholds.min_segment_px:
                regions[m] = len(labels)
                labels.append("door")
                scores.append(0.6 + 0.3 * door.score)
    return regions, labels, scores, boxes
