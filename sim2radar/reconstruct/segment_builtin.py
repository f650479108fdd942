"""Stage 2 ``builtin`` backend: classical segmentation of RGB + depth + normals, geometric labels.

No learned weights. The method, step by step:

1. Back-project the (metric, e.g. LiDAR-completed) depth; normals from the point-grid gradients.
2. Gravity from the rig calibration when the frame carries one (``FrameInput.up_cam``), else
   from the horizontal and vertical planes, checked against the image's near-vertical line
   segments (``backproject.estimate_up`` + ``vertical_line_planes``; a roughly level camera is
   assumed), giving a level frame: x forward, y left, z up, origin at the camera.
   With LiDAR (``lidar_floor``), the floor plane fitted to the raw returns of the lowest beams
   (``backproject.find_floor``) fixes up and the floor level when its returns lie on
   up-facing surfaces of the depth map (not where those beams hit the walls first). When the
   depth stage already searched for the floor and completed the image down to it (the
   ``lidar`` backend's ``floor_fill``: ``DepthResult.info["up_cam"]`` and ``["floor"]``), its up
   and floor are used.
3. Edges between neighbouring pixels where the normal turns by more than ``normal_thresh_deg``,
   the depth jumps (relative jump above the largest a continuous surface at
   ``max_incidence_deg`` could make), the local plane offset n·p steps (a door a few cm proud
   of or set into its wall), or the smoothed CIE-Lab colour differs by more than
   ``colour_thresh`` (ΔE*ab, CIE 1976). Connected components of the edge-free pixels are the
   seed regions; tiny ones and the edge pixels join their nearest region.
4. Adjacent regions that are coplanar (normals within ``merge_normal_deg``, plane offsets within
   ``merge_offset_m``) and alike in colour (ΔE < ``merge_colour_thresh``) are merged
   (union-find), so tile grout, texture and shading do not fragment a wall or floor.
5. Labels from geometry in the level frame: horizontal up-facing regions near the lowest level
   are ``floor``, down-facing ones near the highest level ``ceiling``; vertical regions are
   ``door`` when door-sized (``door_width_m`` × ``door_height_m``), standing on the floor and
   ending below the ceiling; ``window`` when a wall-set rectangle with a sill; ``handrail`` when
   long, thin and at hand height; small red regions ``fire_extinguisher``; remaining large
   vertical regions ``wall``; the rest ``clutter``. A region cut by the top *and* a side
   border has neither its height nor its width measured, so the size rules do not make it a
   door. Vertical regions standing ``proud_m`` in front of a large wall are furniture
   (``clutter``) when below door height, or up to it but facing as the wall does (a cabinet's
   front; a leaf swung out of its doorway is turned by its swing): a door is flush with its
   wall or set into it. Small vertical pieces lying on a large wall's plane are that wall.
6. Floor and ceiling by room geometry: points below the floor level (above the ceiling) —
   depth a LiDAR completion extrapolated from a wall into the band under its lowest beam — and
   pixels without depth under the lowest (over the highest) measured pixel of their column
   are floor (ceiling) when their viewing ray meets that plane in front of every wall plane.
7. Wall openings: pixels seen behind a wall plane through a rectangle of it are doors (bottom
   near the floor, door height) or windows (with a sill); their doorway boxes are measured on
   the wall plane.
8. Door frames on the rectified wall planes (:mod:`sim2radar.reconstruct.facade`): two posts
   0.85–2 m apart standing on the floor, joined by a lintel at door height, found from oriented
   image edges whatever the leaf's colour or swing; their doorway boxes come first and their
   pixels become ``door`` segments (``facade=False`` turns this off, ``facade_options`` sets
   :class:`~sim2radar.reconstruct.facade.FacadeConfig`). A doorway cut by the image border is
   found from its one seen post and a lintel running from it to the border.

The options are a frozen
:class:`~sim2radar.reconstruct.segment_builtin_config.SegmenterConfig`: the keyword options of
:class:`BuiltinSegments` name the main thresholds; every other number the steps compare against
is a field of :class:`~sim2radar.reconstruct.segment_builtin_thresholds.SegmenterThresholds`,
grouped by step, with its unit (``thresholds`` option). Each call makes a
:class:`~sim2radar.reconstruct.segment_builtin_config.SegmentContext` (the frame in the level
frame, its colour, its floor and ceiling levels) and passes it to the step functions; no state
outlives the call, so one :class:`BuiltinSegments` is safe to share between threads.

Where each part is:

- this module — :func:`segment_frame`, the stage entry (steps 1–2 and the order of the rest),
  the seed regions (3, :func:`seed_regions`) and their merge (4, :func:`merge_regions`);
  :class:`BuiltinSegments`, the registered backend, holds a config and calls it;
- :mod:`~sim2radar.reconstruct.segment_builtin_config` — the config and the per-call context;
- :mod:`~sim2radar.reconstruct.segment_builtin_labels` — the geometric labels (5);
- :mod:`~sim2radar.reconstruct.segment_builtin_geometry` — the shape of a region
  (:func:`region_geometry`) and label-map primitives;
- :mod:`~sim2radar.reconstruct.segment_builtin_walls` — wall planes, furniture proud of a wall,
  pieces flush with it (5), floor and ceiling by room geometry (6);
- :mod:`~sim2radar.reconstruct.segment_builtin_doors` — door leaves grown from their fragment
  (5), wall openings (7), door frames on the rectified walls (8);
- :mod:`~sim2radar.reconstruct.segment_builtin_thresholds` — the tuning thresholds.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from sim2radar.reconstruct.backproject import (
    FloorPlane,
    find_floor,
    finite_rows,
    gravity_up,
    level_from_camera,
    points_from_depth,
    surface_normals,
)
from sim2radar.reconstruct.segment_builtin_config import SegmentContext, SegmenterConfig
from sim2radar.reconstruct.segment_builtin_doors import (
    facade_doors,
    grow_doors,
    wall_openings,
)
from sim2radar.reconstruct.segment_builtin_geometry import (
    SegmentGeometry,
    UnionFind,
    fill_columns,
    fill_nearest,
    footprint_gap_m,
    region_geometry,
)
from sim2radar.reconstruct.segment_builtin_labels import door_like, label_regions
from sim2radar.reconstruct.segment_builtin_thresholds import SegmenterThresholds
from sim2radar.reconstruct.segment_builtin_walls import (
    below_floor,
    flush_with_walls,
    proud_of_walls,
)
from sim2radar.reconstruct.types import (
    SEGMENT_BACKENDS,
    DepthResult,
    FrameInput,
    ReconstructionInputError,
    Segments,
)

__all__ = ["BuiltinSegments", "SegmentContext", "SegmentGeometry", "SegmenterConfig",
           "SegmenterThresholds", "compact_regions", "footprint_gap_m", "horizontal_level",
           "lab_image", "merge_regions", "region_geometry", "seed_regions", "segment_frame"]


@SEGMENT_BACKENDS.register("builtin")
class BuiltinSegments:
    """Weight-free segmentation + geometric labelling (see the module docstring).

    A holder of a frozen :class:`~sim2radar.reconstruct.segment_builtin_config.SegmenterConfig`
    whose :meth:`segment` runs :func:`segment_frame`; it keeps nothing of a call, so one
    instance may segment frames on any number of threads at once.

    Keyword options (all optional; defaults suit 640×480 corridor images and scale with size;
    each is a field of ``SegmenterConfig``, documented there with its unit):
    ``normal_thresh_deg`` (20), ``colour_thresh`` (ΔE 14), ``max_incidence_deg`` (84),
    ``min_region_frac`` (3e-4 of the image), ``merge_normal_deg`` (12), ``merge_offset_m``
    (0.06), ``merge_colour_thresh`` (ΔE 12), ``fill_no_depth`` (True: pixels without depth join
    the nearest region), ``door_width_m`` ((0.55, 2.0)), ``door_height_m``
    ((1.85, 2.3); leaves are 1.98–2.13 m in the common standards — DIN 18101, US 6'8"–7'0" —
    and the measured top adds up to ~0.1 m: a taller rectangle standing on the floor is a
    wall's surface, e.g. a wall facing the camera and cut by the image's top border),
    ``floor_tolerance_m`` (0.25), ``offset_thresh_m`` (0.015; plane-offset step
    between neighbours, plus 0.4 % of the depth), ``door_thickness_m`` (0.17,
    :data:`sim2radar.boxes.DOOR_THICKNESS_M`; depth of the doorway boxes measured from wall
    openings), ``below_floor_m`` (0.08; points this far below
    the floor / above the ceiling are floor / ceiling), ``door_partial`` (True: tall planar
    fragments standing near the floor are doors), ``door_bottom_max_m`` (0.75; an opening of
    door height whose bottom is lower than this is a door, higher a window), ``grow_colour``
    (ΔE 15; colour step that bounds a door leaf grown from its lower fragment), ``proud_m``
    ((0.12, 0.7); a vertical region this far in front of a large wall is furniture),
    ``proud_split`` (True: such pixels inside a wall's own region are split off too),
    ``lidar_floor`` (True: floor plane and up from the raw LiDAR returns when given), ``facade``
    (True: door frames on rectified wall planes, step 8), ``facade_options`` (a dict of
    :class:`~sim2radar.reconstruct.facade.FacadeConfig` fields) and ``thresholds`` (a dict of
    :class:`~sim2radar.reconstruct.segment_builtin_thresholds.SegmenterThresholds` fields: every
    other threshold of the steps, named with its unit).

    Attributes
    ----------
    config : SegmenterConfig — the options.
    """

    def __init__(self, **options) -> None:
        self.config = SegmenterConfig.from_options(**options)

    def segment(self, frame: FrameInput, depth: DepthResult) -> Segments:
        """Segments and geometric labels of ``frame`` on ``depth`` (:func:`segment_frame`)."""
        return segment_frame(frame, depth, self.config)


# -- stage entry ----------------------------------------------------------------------------
def segment_frame(frame: FrameInput, depth: DepthResult,
                  config: SegmenterConfig = SegmenterConfig()) -> Segments:
    """Stage 2 of the reconstruction with the ``builtin`` method (the module docstring's steps
    1–8) on one frame.

    Parameters
    ----------
    frame : FrameInput — the image, intrinsics, LiDAR returns and rig calibration.
    depth : DepthResult — metric z-depth [m] of every pixel (0 / NaN: none), and the floor the
        depth stage found (``info["up_cam"]``, ``info["floor"]``) when it searched for it.
    config : SegmenterConfig

    Returns
    -------
    Segments — the segment of every pixel (-1: none, with ``fill_no_depth=False``), labels,
    scores, up in the camera frame, the doorway boxes found (level frame,
    ``x y z dx dy dz heading``) and ``info`` (``floor_z_m``, ``ceiling_z_m`` [m],
    ``n_segments``).

    Raises
    ------
    ReconstructionInputError — depth of another shape than the image, too few pixels with
        depth, or no segment found.
    """
    k = frame.intrinsics
    depth_m = np.asarray(depth.depth_m, dtype=np.float32)
    if depth_m.shape != frame.shape:
        raise ReconstructionInputError(
            f"{frame.name}: depth is {depth_m.shape} but the image is {frame.shape}"
        )
    points = points_from_depth(depth_m, k)
    valid = finite_rows(points)
    if valid.sum() < config.thresholds.min_valid_px:
        raise ReconstructionInputError(
            f"{frame.name}: no segments — the depth map has {int(valid.sum())} valid pixels; "
            "check the depth backend (LiDAR in view? model output?)"
        )
    normals = surface_normals(points)
    floor = None
    if "up_cam" in depth.info and "floor" in depth.info:
        # the depth stage already searched for the floor (the lidar backend's floor_fill)
        # and completed the image down to it: same up, same floor
        up = np.asarray(depth.info["up_cam"], np.float64)
        if depth.info["floor"]:
            floor = FloorPlane.from_info(depth.info["floor"])
    else:
        up = gravity_up(normals, frame.rgb, k, frame.up_cam)
        if config.lidar_floor:
            # the raw returns of the lowest beams measure the floor to centimetres; without
            # them the rig's calibrated camera height gives it
            floor = find_floor(normals, up, k, frame.lidar_points, frame.camera_height_m)
    floor_z_known = None
    if floor is not None:
        floor_z_known = -floor.height_m
        up = floor.normal
    rot = level_from_camera(up)[:3, :3]
    pl = points @ rot.T

    lab = lab_image(frame.rgb, config)
    regions = seed_regions(points, normals, lab, valid, k.fx, config, up)
    nl = normals @ rot.T
    floor_z = (horizontal_level(pl, nl, config, up=True) if floor_z_known is None
               else floor_z_known)
    ctx = SegmentContext(config, pl, pixel_angle_rad=1.0 / k.fx, lab=lab, rgb=frame.rgb,
                         rotation=rot, intrinsics=k)
    regions = merge_regions(ctx, regions, floor_z)
    if config.fill_no_depth:
        # pixels without depth (e.g. below the LiDAR's lowest beam) join the nearest
        # region in the image: they get a label and material, but no 3D point
        regions = fill_nearest(fill_columns(regions), np.ones_like(valid))
    labels, scores, info = label_regions(ctx, regions, floor_z_known)
    ctx = ctx.with_levels(info["floor_z_m"], info["ceiling_z_m"])
    regions, labels, scores, proud = proud_of_walls(ctx, regions, labels, scores)
    labels = flush_with_walls(ctx, regions, labels, skip=proud)
    if config.door_partial:
        regions, labels, scores = grow_doors(ctx, regions, labels, scores, skip=proud)
    rays = points_from_depth(np.ones(frame.shape, np.float32), k) @ rot.T
    regions, labels, scores = below_floor(ctx, regions, labels, scores, rays)
    regions, labels, scores, openings = wall_openings(ctx, regions, labels, scores)
    if config.facade:
        regions, labels, scores, found = facade_doors(ctx, regions, labels, scores)
        openings = found + openings
    seg, labels, scores = compact_regions(regions, labels, scores)
    if not labels:
        raise ReconstructionInputError(f"{frame.name}: no segments found")
    return Segments(seg, tuple(labels), np.asarray(scores, np.float32), up_cam=up,
                    door_boxes_level=np.asarray(openings, np.float32).reshape(-1, 7),
                    info={**info, "n_segments": len(labels)})


# -- steps ----------------------------------------------------------------------------------
def lab_image(rgb: np.ndarray, config: SegmenterConfig) -> np.ndarray:
    """(H, W, 3) float32 — the image smoothed by a Gaussian of σ = max(``colour_blur_sigma_px``,
    width / ``colour_blur_ref_width_px``) [px], in CIE-Lab (L* in [0, 100], a*/b* in about
    [-127, 127])."""
    cfg = config.thresholds
    sigma = max(cfg.colour_blur_sigma_px, rgb.shape[1] / cfg.colour_blur_ref_width_px)
    blur = cv2.GaussianBlur(rgb, (0, 0), sigma)
    lab = cv2.cvtColor(blur.astype(np.float32) / 255.0, cv2.COLOR_RGB2LAB)
    return lab  # L in [0, 100], a/b in about [-127, 127]


def seed_regions(points: np.ndarray, normals: np.ndarray, lab: np.ndarray, valid: np.ndarray,
                 focal_px: float, config: SegmenterConfig, up=None) -> np.ndarray:
    """Seed regions (step 3): the label map (H, W) of the connected components of the pixels
    with no edge to a neighbour.

    An edge lies between neighbours whose depth jumps (relative jump above
    tan(``max_incidence_deg``) / ``focal_px`` + ``depth_jump_rel``), whose normals turn by more
    than ``normal_thresh_deg``, whose colours (``lab``) differ by more than ``colour_thresh``,
    whose plane offsets n·p step by more than ``offset_thresh_m`` + 0.4 % of the depth, or whose
    orientation classes (vertical, up, down, oblique about ``up``, camera frame) differ.
    Components smaller than ``min_region_frac`` of the image, and the edge pixels, join their
    nearest region; pixels without depth stay -1. ``points`` and ``normals`` are (H, W, 3) in
    the camera frame [m].
    """
    cfg = config.thresholds
    z = np.where(valid, points[..., 2], np.nan)
    # orientation class per pixel (vertical / facing up / facing down / oblique): a hard
    # boundary where a smoothed depth map bends gradually from a wall into the floor
    if up is None:
        up = np.array([0.0, -1.0, 0.0])
    with np.errstate(invalid="ignore"):
        nz = normals @ np.asarray(up, np.float64)
    orient = np.full(z.shape, 3, np.int8)
    orient[np.abs(nz) < math.sin(math.radians(cfg.orient_class_deg))] = 0
    orient[nz > math.cos(math.radians(cfg.orient_class_deg))] = 1
    orient[nz < -math.cos(math.radians(cfg.orient_class_deg))] = 2
    cos_n = math.cos(math.radians(config.normal_thresh_deg))
    jump = math.tan(math.radians(config.max_incidence_deg)) / focal_px + cfg.depth_jump_rel

    def broken(sl_a, sl_b):
        za, zb = z[sl_a], z[sl_b]
        with np.errstate(invalid="ignore"):
            dj = np.abs(za - zb) / np.minimum(za, zb) > jump
            dn = np.sum(normals[sl_a] * normals[sl_b], axis=-1) < cos_n
            dc = np.linalg.norm(lab[sl_a] - lab[sl_b], axis=-1) > config.colour_thresh
            # plane-offset step: a door proud of / set into a coplanar wall
            off = np.abs(np.sum(normals[sl_a] * points[sl_a], axis=-1)
                         - np.sum(normals[sl_b] * points[sl_b], axis=-1))
            do = off > config.offset_thresh_m + cfg.offset_step_per_m * np.minimum(za, zb)
        do_ = orient[sl_a] != orient[sl_b]
        return dj | dn | dc | do | do_ | ~(valid[sl_a] & valid[sl_b])

    edge = np.zeros(valid.shape, bool)
    edge[:, :-1] |= broken((slice(None), slice(None, -1)), (slice(None), slice(1, None)))
    edge[:-1, :] |= broken((slice(None, -1), slice(None)), (slice(1, None), slice(None)))
    core = valid & ~edge
    n, cc, stats, _ = cv2.connectedComponentsWithStats(core.astype(np.uint8), connectivity=4)
    min_px = max(cfg.min_region_px, int(config.min_region_frac * valid.size))
    keep = stats[:, cv2.CC_STAT_AREA] >= min_px
    keep[0] = False
    lut = np.full(n, -1, np.int64)
    lut[keep] = np.arange(int(keep.sum()))
    labels = lut[cc]
    return fill_nearest(labels, valid)


def horizontal_level(pl: np.ndarray, nl: np.ndarray, config: SegmenterConfig,
                     up: bool) -> float | None:
    """Median height [m] of the pixels on horizontal surfaces facing up (floor, ``up``) or down
    (ceiling); None with fewer than ``level_min_px`` of them. ``pl`` and ``nl`` are the
    level-frame points [m] and normals (H, W, 3)."""
    cfg = config.thresholds
    with np.errstate(invalid="ignore"):
        if up:
            sel = ((nl[..., 2] > cfg.level_normal_cos)
                   & (pl[..., 2] < -cfg.floor_below_camera_m))
        else:
            sel = ((nl[..., 2] < -cfg.level_normal_cos)
                   & (pl[..., 2] > cfg.ceiling_above_camera_m))
    if sel.sum() < cfg.level_min_px:
        return None
    return float(np.median(pl[..., 2][sel]))


def merge_regions(ctx: SegmentContext, regions: np.ndarray,
                  floor_z: float | None = None) -> np.ndarray:
    """Merge adjacent coplanar regions of alike colour (step 4; union-find, up to
    ``merge_passes`` rounds): mean colours (``ctx.lab``) within ``merge_colour_thresh``, normals
    within ``merge_normal_deg`` and each centroid within ``merge_offset_m`` of the other's
    plane. Two door-sized rectangles standing on the floor at ``floor_z`` [m] stay apart
    (:func:`~sim2radar.reconstruct.segment_builtin_labels.door_like`). Returns the label map
    with consecutive ids."""
    opts, cfg, pl, lab = ctx.config, ctx.thresholds, ctx.points_level, ctx.lab
    n = int(regions.max()) + 1
    if n <= 1:
        return regions
    for _ in range(cfg.merge_passes):
        n = int(regions.max()) + 1
        flat = regions.ravel()
        ok = flat >= 0
        cnt = np.bincount(flat[ok], minlength=n).astype(np.float64)
        geo = [None] * n
        col = np.zeros((n, 3))
        for c in range(3):
            col[:, c] = np.bincount(flat[ok], lab[..., c].ravel()[ok], minlength=n)
        col /= np.maximum(cnt, 1)[:, None]
        # adjacent pairs
        pairs = set()
        for a, b in ((regions[:, :-1], regions[:, 1:]), (regions[:-1, :], regions[1:, :])):
            m = (a != b) & (a >= 0) & (b >= 0)
            pa, pb = a[m], b[m]
            codes = np.unique(np.minimum(pa, pb) * n + np.maximum(pa, pb))
            pairs.update(codes.tolist())
        uf = UnionFind(n)
        cos_m = math.cos(math.radians(opts.merge_normal_deg))
        merged = False
        for code in sorted(pairs):
            a, b = divmod(code, n)
            if np.linalg.norm(col[a] - col[b]) > opts.merge_colour_thresh:
                continue
            for i in (a, b):
                if geo[i] is None:
                    geo[i] = region_geometry(pl, regions == i,
                                             max_points=cfg.quick_fit_points,
                                             pixel_angle_rad=ctx.pixel_angle_rad)
            ga, gb = geo[a], geo[b]
            if ga.n_px < 3 or gb.n_px < 3:
                continue
            # two door-sized rectangles side by side stay apart (neighbouring doors whose
            # wall strip is too thin to survive; double-door leaves are joined later)
            if door_like(opts, ga, floor_z) and door_like(opts, gb, floor_z):
                continue
            if abs(ga.normal @ gb.normal) < cos_m:
                continue
            d = gb.centroid - ga.centroid
            if abs(ga.normal @ d) > opts.merge_offset_m or abs(gb.normal @ d) > opts.merge_offset_m:
                continue
            uf.union(a, b)
            merged = True
        if not merged:
            break
        roots = np.array([uf.find(i) for i in range(n)])
        _, new = np.unique(roots, return_inverse=True)
        regions = np.where(regions >= 0, new[np.clip(regions, 0, None)], -1)
    return regions


def compact_regions(regions: np.ndarray, labels, scores):
    """The label map (int32) with the region ids that hold pixels renumbered 0..S-1, and
    their labels and scores."""
    ids = np.unique(regions[regions >= 0])
    remap = np.full(int(regions.max()) + 2, -1, np.int64)
    remap[ids] = np.arange(len(ids))
    seg = np.where(regions >= 0, remap[np.clip(regions, 0, None)], -1).astype(np.int32)
    return seg, [labels[i] for i in ids], [scores[i] for i in ids]
