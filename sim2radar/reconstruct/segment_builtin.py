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

The keyword options of :class:`BuiltinSegments` name the main thresholds; every other number
the steps compare against is a field of
:class:`~sim2radar.reconstruct.segment_builtin_thresholds.SegmenterThresholds`, grouped by step,
with its unit (``thresholds`` option).

Where each part is:

- this module — :class:`BuiltinSegments`: the options, the stage entry (steps 1–2 and the order
  of the rest), the seed regions (3), their merge (4) and the geometric labels (5);
- :mod:`~sim2radar.reconstruct.segment_builtin_geometry` — the shape of a region
  (:func:`region_geometry`) and label-map primitives (pure functions);
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

from sim2radar.boxes import DOOR_THICKNESS_M
from sim2radar.reconstruct.backproject import (
    FloorPlane,
    find_floor,
    gravity_up,
    level_from_camera,
    points_from_depth,
    surface_normals,
)
from sim2radar.reconstruct.facade import FacadeConfig
from sim2radar.reconstruct.segment_builtin_doors import DoorSteps
from sim2radar.reconstruct.segment_builtin_geometry import (
    SegmentGeometry,
    UnionFind,
    fill_columns,
    fill_nearest,
    footprint_gap_m,
    region_geometry,
)
from sim2radar.reconstruct.segment_builtin_thresholds import (
    SegmenterThresholds,
    config_from_options,
)
from sim2radar.reconstruct.types import (
    SEGMENT_BACKENDS,
    DepthResult,
    FrameInput,
    ReconstructionInputError,
    Segments,
)

__all__ = ["BuiltinSegments", "SegmentGeometry", "SegmenterThresholds", "region_geometry",
           "footprint_gap_m"]


@SEGMENT_BACKENDS.register("builtin")
class BuiltinSegments(DoorSteps):
    """Weight-free segmentation + geometric labelling (see the module docstring).

    Keyword options (all optional; defaults suit 640×480 corridor images and scale with size):
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
    """

    def __init__(
        self,
        *,
        normal_thresh_deg: float = 20.0,
        colour_thresh: float = 14.0,
        max_incidence_deg: float = 84.0,
        min_region_frac: float = 3e-4,
        merge_normal_deg: float = 12.0,
        merge_offset_m: float = 0.06,
        merge_colour_thresh: float = 12.0,
        door_width_m: tuple[float, float] = (0.55, 2.0),
        door_height_m: tuple[float, float] = (1.85, 2.3),
        floor_tolerance_m: float = 0.25,
        offset_thresh_m: float = 0.015,
        door_thickness_m: float = DOOR_THICKNESS_M,
        fill_no_depth: bool = True,
        below_floor_m: float = 0.08,
        door_partial: bool = True,
        door_bottom_max_m: float = 0.75,
        grow_colour: float = 15.0,
        proud_m: tuple[float, float] = (0.12, 0.7),
        proud_split: bool = True,
        lidar_floor: bool = True,
        facade: bool = True,
        facade_options: dict | None = None,
        thresholds: dict | None = None,
    ) -> None:
        self.normal_thresh_deg = float(normal_thresh_deg)
        self.colour_thresh = float(colour_thresh)
        self.max_incidence_deg = float(max_incidence_deg)
        self.min_region_frac = float(min_region_frac)
        self.merge_normal_deg = float(merge_normal_deg)
        self.merge_offset_m = float(merge_offset_m)
        self.merge_colour_thresh = float(merge_colour_thresh)
        self.door_width_m = tuple(float(x) for x in door_width_m)
        self.door_height_m = tuple(float(x) for x in door_height_m)
        self.floor_tolerance_m = float(floor_tolerance_m)
        self.offset_thresh_m = float(offset_thresh_m)
        self.door_thickness_m = float(door_thickness_m)
        self.fill_no_depth = bool(fill_no_depth)
        self.below_floor_m = float(below_floor_m)
        self.door_partial = bool(door_partial)
        self.door_bottom_max_m = float(door_bottom_max_m)
        self.grow_colour = float(grow_colour)
        self.proud_m = tuple(float(x) for x in proud_m)
        self.proud_split = bool(proud_split)
        self.lidar_floor = bool(lidar_floor)
        self.facade = bool(facade)
        self.facade_config = config_from_options(FacadeConfig, facade_options,
                                                 "segments.options.facade_options")
        self.thresholds = config_from_options(SegmenterThresholds, thresholds,
                                              "segments.options.thresholds")
        self._pixel_angle: float | None = None

    # -- stage entry ------------------------------------------------------------------------
    def segment(self, frame: FrameInput, depth: DepthResult) -> Segments:
        k = frame.intrinsics
        depth_m = np.asarray(depth.depth_m, dtype=np.float32)
        if depth_m.shape != frame.shape:
            raise ReconstructionInputError(
                f"{frame.name}: depth is {depth_m.shape} but the image is {frame.shape}"
            )
        points = points_from_depth(depth_m, k)
        valid = np.isfinite(points).all(axis=-1)
        if valid.sum() < self.thresholds.min_valid_px:
            raise ReconstructionInputError(
                f"{frame.name}: no segments — the depth map has {int(valid.sum())} valid pixels; "
                "check the depth backend (LiDAR in view? model output?)"
            )
        h, w = frame.shape
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
            if self.lidar_floor:
                # the raw returns of the lowest beams measure the floor to centimetres; without
                # them the rig's calibrated camera height gives it
                floor = find_floor(normals, up, k, frame.lidar_points, frame.camera_height_m)
        floor_z_known = None
        if floor is not None:
            floor_z_known = -floor.height_m
            up = floor.normal
        rot = level_from_camera(up)[:3, :3]
        pl = points @ rot.T

        lab = self._lab(frame.rgb, w)
        regions = self._regions(points, normals, lab, valid, k.fx, up)
        nl = normals @ rot.T
        floor_z = self._level(pl, nl, up=True) if floor_z_known is None else floor_z_known
        self._pixel_angle = 1.0 / k.fx
        regions = self._merge(regions, pl, lab, valid, floor_z)
        if self.fill_no_depth:
            # pixels without depth (e.g. below the LiDAR's lowest beam) join the nearest
            # region in the image: they get a label and material, but no 3D point
            regions = fill_nearest(fill_columns(regions), np.ones_like(valid))
        labels, scores, info = self._label(regions, pl, frame.rgb, floor_z_known)
        regions, labels, scores, proud = self._proud_of_walls(regions, labels, scores, pl,
                                                              info["floor_z_m"])
        labels = self._flush_with_walls(regions, labels, pl, skip=proud)
        if self.door_partial:
            regions, labels, scores = self._grow_doors(regions, labels, scores, pl, lab,
                                                       info["floor_z_m"], info["ceiling_z_m"],
                                                       skip=proud)
        rays = points_from_depth(np.ones(frame.shape, np.float32), k) @ rot.T
        regions, labels, scores = self._below_floor(regions, labels, scores, pl, rays,
                                                    info["floor_z_m"], info["ceiling_z_m"])
        regions, labels, scores, openings = self._wall_openings(
            regions, labels, scores, pl, info["floor_z_m"], info["ceiling_z_m"])
        if self.facade:
            regions, labels, scores, found = self._facade_doors(
                regions, labels, scores, pl, rot, k, frame.rgb, info["floor_z_m"],
                info["ceiling_z_m"])
            openings = found + openings
        seg, labels, scores = self._compact(regions, labels, scores)
        if not labels:
            raise ReconstructionInputError(f"{frame.name}: no segments found")
        return Segments(seg, tuple(labels), np.asarray(scores, np.float32), up_cam=up,
                        door_boxes_level=np.asarray(openings, np.float32).reshape(-1, 7),
                        info={**info, "n_segments": len(labels)})

    # -- steps ------------------------------------------------------------------------------
    def _lab(self, rgb: np.ndarray, width: int) -> np.ndarray:
        cfg = self.thresholds
        sigma = max(cfg.colour_blur_sigma_px, width / cfg.colour_blur_ref_width_px)
        blur = cv2.GaussianBlur(rgb, (0, 0), sigma)
        lab = cv2.cvtColor(blur.astype(np.float32) / 255.0, cv2.COLOR_RGB2LAB)
        return lab  # L in [0, 100], a/b in about [-127, 127]

    def _regions(self, points, normals, lab, valid, focal_px, up=None) -> np.ndarray:
        cfg = self.thresholds
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
        cos_n = math.cos(math.radians(self.normal_thresh_deg))
        jump = math.tan(math.radians(self.max_incidence_deg)) / focal_px + cfg.depth_jump_rel

        def broken(sl_a, sl_b):
            za, zb = z[sl_a], z[sl_b]
            with np.errstate(invalid="ignore"):
                dj = np.abs(za - zb) / np.minimum(za, zb) > jump
                dn = np.sum(normals[sl_a] * normals[sl_b], axis=-1) < cos_n
                dc = np.linalg.norm(lab[sl_a] - lab[sl_b], axis=-1) > self.colour_thresh
                # plane-offset step: a door proud of / set into a coplanar wall
                off = np.abs(np.sum(normals[sl_a] * points[sl_a], axis=-1)
                             - np.sum(normals[sl_b] * points[sl_b], axis=-1))
                do = off > self.offset_thresh_m + cfg.offset_step_per_m * np.minimum(za, zb)
            do_ = orient[sl_a] != orient[sl_b]
            return dj | dn | dc | do | do_ | ~(valid[sl_a] & valid[sl_b])

        edge = np.zeros(valid.shape, bool)
        edge[:, :-1] |= broken((slice(None), slice(None, -1)), (slice(None), slice(1, None)))
        edge[:-1, :] |= broken((slice(None, -1), slice(None)), (slice(1, None), slice(None)))
        core = valid & ~edge
        n, cc, stats, _ = cv2.connectedComponentsWithStats(core.astype(np.uint8), connectivity=4)
        min_px = max(cfg.min_region_px, int(self.min_region_frac * valid.size))
        keep = stats[:, cv2.CC_STAT_AREA] >= min_px
        keep[0] = False
        lut = np.full(n, -1, np.int64)
        lut[keep] = np.arange(int(keep.sum()))
        labels = lut[cc]
        return fill_nearest(labels, valid)

    def _level(self, pl, nl, up: bool) -> float | None:
        """Median height of pixels on horizontal surfaces facing up (floor) or down (ceiling)."""
        cfg = self.thresholds
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

    def _door_like(self, g: SegmentGeometry, floor_z: float | None) -> bool:
        """Door-sized vertical rectangle standing on the floor (before labelling)."""
        if floor_z is None or g.vertical_cos > self.thresholds.door_like_max_vertical_cos:
            return False
        return (g.z_min_m < floor_z + self.floor_tolerance_m
                and self.door_height_m[0] <= g.height_m <= self.door_height_m[1]
                and g.width_m <= self.door_width_m[1])

    def _merge(self, regions, pl, lab, valid, floor_z=None) -> np.ndarray:
        n = int(regions.max()) + 1
        if n <= 1:
            return regions
        for _ in range(self.thresholds.merge_passes):
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
            cos_m = math.cos(math.radians(self.merge_normal_deg))
            merged = False
            for code in sorted(pairs):
                a, b = divmod(code, n)
                if np.linalg.norm(col[a] - col[b]) > self.merge_colour_thresh:
                    continue
                for i in (a, b):
                    if geo[i] is None:
                        geo[i] = region_geometry(pl, regions == i,
                                                 max_points=self.thresholds.quick_fit_points,
                                                 pixel_angle_rad=self._pixel_angle)
                ga, gb = geo[a], geo[b]
                if ga.n_px < 3 or gb.n_px < 3:
                    continue
                # two door-sized rectangles side by side stay apart (neighbouring doors whose
                # wall strip is too thin to survive; double-door leaves are joined later)
                if self._door_like(ga, floor_z) and self._door_like(gb, floor_z):
                    continue
                if abs(ga.normal @ gb.normal) < cos_m:
                    continue
                d = gb.centroid - ga.centroid
                if abs(ga.normal @ d) > self.merge_offset_m or abs(gb.normal @ d) > self.merge_offset_m:
                    continue
                uf.union(a, b)
                merged = True
            if not merged:
                break
            roots = np.array([uf.find(i) for i in range(n)])
            _, new = np.unique(roots, return_inverse=True)
            regions = np.where(regions >= 0, new[np.clip(regions, 0, None)], -1)
        return regions

    def _label(self, regions, pl, rgb, floor_z_known=None):
        cfg = self.thresholds
        n = int(regions.max()) + 1
        geos = [region_geometry(pl, regions == i, pixel_angle_rad=self._pixel_angle)
                for i in range(n)]
        hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
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
        tol = self.floor_tolerance_m
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
                label, score = self._vertical_label(g, floor_z, ceil_z, bool(downs),
                                                    float(value[i]))
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

    def _vertical_label(self, g: SegmentGeometry, floor_z: float, ceil_z: float,
                        ceiling_seen: bool, brightness: float = 1.0) -> tuple[str, float]:
        cfg = self.thresholds
        tol = self.floor_tolerance_m
        on_floor = g.z_min_m < floor_z + tol
        below_ceiling = g.z_max_m < ceil_z - cfg.below_ceiling_m or not ceiling_seen
        w_lo, w_hi = self.door_width_m
        h_lo, h_hi = self.door_height_m
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
        if (sized and self.door_partial and g.z_min_m < floor_z + cfg.fragment_max_bottom_m
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

    @staticmethod
    def _compact(regions, labels, scores):
        ids = np.unique(regions[regions >= 0])
        remap = np.full(int(regions.max()) + 2, -1, np.int64)
        remap[ids] = np.arange(len(ids))
        seg = np.where(regions >= 0, remap[np.clip(regions, 0, None)], -1).astype(np.int32)
        return seg, [labels[i] for i in ids], [scores[i] for i in ids]
