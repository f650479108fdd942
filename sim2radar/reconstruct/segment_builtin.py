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
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from sim2radar.boxes import DOOR_THICKNESS_M, wrap_heading
from sim2radar.reconstruct.backproject import (
    FloorPlane,
    column_extent,
    find_floor,
    gravity_up,
    level_from_camera,
    points_from_depth,
    surface_normals,
)
from sim2radar.reconstruct.facade import FacadeConfig, WallPlane, find_facade_doors
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


@dataclasses.dataclass(frozen=True)
class SegmentGeometry:
    """Shape of one region in the level frame (x forward, y left, z up) [m].

    Attributes
    ----------
    n_px : int — pixel count.
    centroid : (3,) float64 [m]
    normal : (3,) float64 — unit plane normal (PCA), facing the camera.
    planarity : float — RMS distance of the points to their plane [m].
    width_m : float [m] — horizontal extent along the plane (1st–99th percentile).
    z_min_m, z_max_m : float [m] — vertical extent (1st / 99th percentile).
    fill : float — pixel count over the area of the region's convex hull in the image.
    borders : str — the image borders the region reaches: any of ``t`` (top), ``b`` (bottom),
        ``l`` (left), ``r`` (right); its extent is cut on those sides.
    """

    n_px: int
    centroid: np.ndarray
    normal: np.ndarray
    planarity: float
    width_m: float
    z_min_m: float
    z_max_m: float
    fill: float
    borders: str

    @property
    def touches_border(self) -> bool:
        """The region reaches the image border (it is partly out of view)."""
        return bool(self.borders)

    @property
    def height_m(self) -> float:
        return self.z_max_m - self.z_min_m

    @property
    def vertical_cos(self) -> float:
        """|n · z|: 1 for a horizontal plane, 0 for a vertical one."""
        return abs(float(self.normal[2]))


def footprint_gap_m(centroid: np.ndarray, normal: np.ndarray, pixel_angle_rad: float | None,
                    min_gap_m: float = 0.25) -> float:
    """Largest gap [m] between neighbouring samples of one surface to still call it
    contiguous: three pixel footprints along the surface (range·pixel angle / cos incidence),
    at least ``min_gap_m``."""
    if not pixel_angle_rad:
        return min_gap_m
    rng = float(np.linalg.norm(centroid))
    cos_inc = abs(float(normal @ centroid)) / max(rng, 1e-9)
    return max(min_gap_m, 3.0 * rng * pixel_angle_rad / max(cos_inc, 0.1))


def region_geometry(points_level: np.ndarray, mask: np.ndarray, max_points: int = 4000,
                    pixel_angle_rad: float | None = None) -> SegmentGeometry:
    """Plane fit and extents of the pixels ``mask`` of a level-frame point map (H, W, 3).

    ``pixel_angle_rad`` (≈ 1/fx) sets the gap that splits the points along the plane
    (:func:`footprint_gap_m`); the width is that of the largest contiguous run."""
    pts = points_level[mask]
    pts = pts[np.isfinite(pts).all(axis=1)].astype(np.float64)
    h, w = mask.shape
    touches = "".join(side for side, edge in (("t", mask[0]), ("b", mask[-1]), ("l", mask[:, 0]),
                                              ("r", mask[:, -1])) if edge.any())
    if len(pts) < 3:
        c = pts.mean(axis=0) if len(pts) else np.zeros(3)
        return SegmentGeometry(len(pts), c, np.array([1.0, 0, 0]), 0.0, 0.0, 0.0, 0.0, 0.0,
                               touches)
    if len(pts) > max_points:
        pts = pts[np.linspace(0, len(pts) - 1, max_points).astype(int)]
    c = pts.mean(axis=0)
    _, s, vt = np.linalg.svd(pts - c, full_matrices=False)
    n = vt[2]
    if n @ c > 0:  # face the camera (origin)
        n = -n
    planarity = float(s[2] / math.sqrt(len(pts)))
    horiz = np.array([-n[1], n[0], 0.0])
    if np.linalg.norm(horiz) < 1e-6:
        horiz = np.array([1.0, 0.0, 0.0])
    horiz /= np.linalg.norm(horiz)
    a = pts @ horiz
    z = pts[:, 2]
    # the largest run along the plane without a gap: stray pixels of a neighbouring surface
    # seen at a grazing angle must not inflate the width
    order = np.argsort(a)
    breaks = np.flatnonzero(np.diff(a[order]) > footprint_gap_m(c, n, pixel_angle_rad))
    if len(breaks):
        keep = max(np.split(order, breaks + 1), key=len)
        a, z = a[keep], z[keep]
    a0, a1 = np.percentile(a, [1, 99])
    z0, z1 = np.percentile(z, [1, 99])
    # fill: pixels over the area of their convex hull in the image (a rectangle seen in
    # perspective projects to a convex quadrilateral, so a whole door gives ~1)
    ij = np.argwhere(mask)
    if len(ij) >= 3:
        hull = cv2.convexHull(ij[:, ::-1].astype(np.int32))
        fill = min(1.0, len(ij) / max(cv2.contourArea(hull) + 0.5 * cv2.arcLength(hull, True) + 1, 1))
    else:
        fill = 0.0
    return SegmentGeometry(int(mask.sum()), c, n, planarity, float(a1 - a0), float(z0), float(z1),
                           float(fill), touches)


def _fill_columns(labels: np.ndarray) -> np.ndarray:
    """Unlabelled pixels below the lowest (above the highest) labelled pixel of their column
    take its label: the bands a sensor misses at the bottom / top of the image continue the
    surface seen at their edge (floor below, ceiling above), not the nearest one sideways."""
    out = labels.copy()
    known = labels >= 0
    h = labels.shape[0]
    has = known.any(axis=0)
    cols = np.flatnonzero(has)
    if not len(cols):
        return out
    first = np.argmax(known, axis=0)
    last = h - 1 - np.argmax(known[::-1], axis=0)
    rows = np.arange(h)[:, None]
    top_lab = labels[first, np.arange(labels.shape[1])]
    bot_lab = labels[last, np.arange(labels.shape[1])]
    above = (rows < first[None, :]) & has[None, :]
    below = (rows > last[None, :]) & has[None, :]
    out = np.where(above, top_lab[None, :], out)
    out = np.where(below, bot_lab[None, :], out)
    return out


class _UnionFind:
    def __init__(self, n: int) -> None:
        self.parent = list(range(n))

    def find(self, i: int) -> int:
        while self.parent[i] != i:
            self.parent[i] = self.parent[self.parent[i]]
            i = self.parent[i]
        return i

    def union(self, a: int, b: int) -> None:
        ra, rb = self.find(a), self.find(b)
        if ra != rb:
            self.parent[max(ra, rb)] = min(ra, rb)


def _fill_nearest(labels: np.ndarray, fillable: np.ndarray) -> np.ndarray:
    """Give every ``fillable`` pixel with label < 0 the label of the nearest labelled pixel."""
    known = labels >= 0
    if known.all() or not known.any():
        return labels
    src = np.where(known, 0, 255).astype(np.uint8)
    _, idx = cv2.distanceTransformWithLabels(src, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    # idx counts zero pixels in row-major order, starting at 1
    lut = np.concatenate([[-1], labels[known]])
    out = labels.copy()
    todo = fillable & ~known
    out[todo] = lut[idx[todo]]
    return out


@SEGMENT_BACKENDS.register("builtin")
class BuiltinSegments:
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
            regions = _fill_nearest(_fill_columns(regions), np.ones_like(valid))
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
        return _fill_nearest(labels, valid)

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
            uf = _UnionFind(n)
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

    def _proud_of_walls(self, regions, labels, scores, pl, floor_z):
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
        to door height and turned from the wall, ``clutter`` otherwise. Returns the regions,
        labels, scores and the region ids turned to clutter (the door growing step skips
        them)."""
        cfg = self.thresholds
        lo, hi = self.proud_m
        valid = np.isfinite(pl).all(axis=-1)
        counts = np.bincount(regions[regions >= 0], minlength=len(labels))
        walls = self._wall_extents(regions, labels, pl, cfg.wall_min_frac, cfg.wall_top_n)
        labels, scores = list(labels), list(scores)
        proud: set[int] = set()
        if self.proud_split:
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
                    g = region_geometry(pl, blob_c, pixel_angle_rad=self._pixel_angle)
                    top = np.percentile(pl[..., 2][blob_c], cfg.proud_top_pct) - floor_z
                    if (top >= self.door_height_m[0]
                            and not self._parallel(g.normal, nrm, cfg.parallel_deg)):
                        # up to door height and turned from the wall: an open leaf swung out of
                        # its doorway when it is door-sized; either way no longer part of the
                        # wall's plane
                        label, score = self._vertical_label(g, floor_z, np.inf, False)
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
            tall = top >= self.door_height_m[0]
            if tall and (top > self.door_height_m[1] or (regions[0] == i).any()):
                continue  # up to the ceiling, or its top not seen: a wall
            normal = region_geometry(pl, regions == i).normal if tall else None
            for wi, nrm, d, along, (s0, s1) in walls:
                if counts[i] >= counts[wi] or (
                        tall and not self._parallel(normal, nrm, cfg.parallel_deg)):
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

    def _flush_with_walls(self, regions, labels, pl, skip=frozenset()):
        """Wall pieces too small for a wall by size — the strips a handrail, a window or a
        shadow cut out of a wall, below the size the vertical rule calls ``wall`` — are
        ``clutter`` only if they stand apart from the walls: a vertical region whose points lie
        on a large wall's plane (80 % within ``flush_tol_m`` + 1 % of their range) and within
        its extent is that wall (furniture stands proud of it, :meth:`_proud_of_walls`)."""
        cfg = self.thresholds
        labels = list(labels)
        valid = np.isfinite(pl).all(axis=-1)
        walls = self._wall_extents(regions, labels, pl, cfg.wall_min_frac, cfg.wall_top_n)
        if not walls:
            return labels
        for i, lbl in enumerate(labels):
            if lbl != "clutter" or i in skip:
                continue
            m = (regions == i) & valid
            if m.sum() < cfg.flush_min_px:
                continue
            pts = pl[m]
            g = region_geometry(pl, m, pixel_angle_rad=self._pixel_angle)
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

    @staticmethod
    def _parallel(normal: np.ndarray, wall_normal: np.ndarray, max_deg: float) -> bool:
        """The region's plane faces the same way as the wall's (within ``max_deg``): standing
        proud of the wall, it is a cabinet's front, not a door leaf swung out of its doorway
        (turned by the swing angle; a leaf swung against the wall is only its thickness proud)."""
        return abs(float(normal[:2] @ wall_normal[:2])) / max(
            float(np.linalg.norm(normal[:2])), 1e-9) > math.cos(math.radians(max_deg))

    def _grow_doors(self, regions, labels, scores, pl, lab, floor_z, ceil_z, skip=frozenset()):
        """Complete door leaves from their lower fragment by colour.

        LiDAR-completed depth blurs a leaf into its wall, so often only the leaf's lower part
        survives as a region (labelled clutter or a small wall) and its upper part joins the
        wall. For each vertical fragment standing on the floor (bottom within
        ``door_bottom_max_m``) whose mean colour differs from its wall's (ΔE > ``grow_colour``),
        the pixels within its image columns that are connected to it and of its colour
        (ΔE < ``grow_colour``) are taken; if that grown region is a door (door width, top at
        door height, below the ceiling) it becomes a ``door`` region."""
        cfg = self.thresholds
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
                                pixel_angle_rad=self._pixel_angle)
            if (g.vertical_cos > cfg.grow_max_vertical_cos
                    or g.z_min_m > floor_z + self.door_bottom_max_m
                    or g.width_m > self.door_width_m[1]):
                continue
            ys, xs = np.nonzero(mask)
            x0, x1 = xs.min(), xs.max() + 1
            close = np.linalg.norm(lab - col[i], axis=-1) < self.grow_colour
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
            if any(big_wall[j] and np.linalg.norm(col[j] - col[i]) < self.grow_colour
                   for j in donors):
                continue
            gg = region_geometry(pl, grown, pixel_angle_rad=self._pixel_angle)
            top = gg.z_max_m - floor_z
            slack = cfg.door_top_slack_m
            if (gg.vertical_cos < cfg.grow_max_vertical_cos
                    and gg.z_min_m < floor_z + self.door_bottom_max_m
                    and self.door_height_m[0] - slack <= top <= self.door_height_m[1] + slack
                    and self.door_width_m[0] <= gg.width_m <= self.door_width_m[1]
                    and gg.z_max_m < ceil_z - cfg.below_ceiling_m):
                regions[grown] = i
                labels[i] = "door"
                scores[i] = 0.5
                taken |= grown
        return regions, labels, scores

    def _below_floor(self, regions, labels, scores, pl, rays, floor_z, ceil_z):
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
        plane; otherwise it sees that wall. ``rays`` (H, W, 3) are the level-frame viewing directions (camera z = 1).
        """
        cfg = self.thresholds
        valid = np.isfinite(pl).all(axis=-1)
        h = valid.shape[0]
        rng = np.linalg.norm(np.where(valid[..., None], pl, 0), axis=-1)
        tol = self.below_floor_m + cfg.below_floor_per_m * rng
        with np.errstate(invalid="ignore"):
            floor_px = valid & (pl[..., 2] < floor_z - tol)
            ceil_px = valid & (pl[..., 2] > ceil_z + tol)
        rows = np.arange(h)[:, None]
        first, last = column_extent(valid)
        if self.fill_no_depth:
            floor_px |= ~valid & (rows > last[None, :]) & (rays[..., 2] < -cfg.fill_ray_slope)
            ceil_px |= ~valid & (rows < first[None, :]) & (rays[..., 2] > cfg.fill_ray_slope)
        # the ray must reach the floor (ceiling) plane in front of every large wall plane:
        # otherwise the pixel sees the wall's lower (upper) part
        walls = self._large_walls(regions, labels, pl, cfg.floor_wall_min_frac,
                                  cfg.floor_wall_top_n)
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

    def _wall_openings(self, regions, labels, scores, pl, floor_z, ceil_z):
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
        cfg = self.thresholds
        h, w = regions.shape
        valid = np.isfinite(pl).all(axis=-1)
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
            plane = self._wall_plane(pl, mask)
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
                if (bottom < self.door_bottom_max_m
                        and self.door_width_m[0] <= width
                        <= self.door_width_m[1] + cfg.opening_door_width_slack_m
                        and self.door_height_m[0] - slack <= top <= self.door_height_m[1] + slack
                        and b1 < ceil_z - cfg.below_ceiling_m):
                    kind = "door"
                elif (max(sill[0], self.door_bottom_max_m) < bottom < sill[1]
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
                    th = self.door_thickness_m
                    cxy = 0.5 * (a0 + a1) * along[:2] + (d - th / 2) * nrm[:2]
                    heading = wrap_heading(math.atan2(along[1], along[0]))
                    boxes.append([float(cxy[0]), float(cxy[1]), float(floor_z + top / 2),
                                  float(width), th, float(top), float(heading)])
        return regions, labels, scores, boxes

    def _wall_plane(self, pl, mask):
        """Vertical plane ``nrm · p = d`` of a wall region (``nrm`` horizontal, facing the
        camera, ``d`` the median offset of its points), its geometry and its valid points; None
        when the region is not vertical, lies within ``wall_min_distance_m`` of the camera, or
        has fewer than ``wall_min_points`` pixels with depth (a region grown over pixels the
        LiDAR missed)."""
        cfg = self.thresholds
        wp = pl[mask & np.isfinite(pl).all(axis=-1)]
        if len(wp) < cfg.wall_min_points:
            return None
        g = region_geometry(pl, mask, pixel_angle_rad=self._pixel_angle)
        if g.vertical_cos > cfg.wall_max_vertical_cos:
            return None
        nrm = np.array([g.normal[0], g.normal[1], 0.0])
        nrm /= np.linalg.norm(nrm)
        d = float(np.median(wp @ nrm))
        return None if d > -cfg.wall_min_distance_m else (nrm, d, g, wp)

    def _large_walls(self, regions, labels, pl, min_frac: float, top: int):
        """``(region id, (nrm, d, geometry, points))`` of the ``wall`` regions among the
        ``top`` largest regions that hold at least ``min_frac`` of the valid pixels and have a
        vertical plane (:meth:`_wall_plane`), largest first."""
        n_valid = int(np.isfinite(pl).all(axis=-1).sum())
        counts = np.bincount(regions[regions >= 0], minlength=len(labels))
        out = []
        for wi in np.argsort(-counts)[:top]:
            if labels[wi] != "wall" or counts[wi] < min_frac * n_valid:
                continue
            plane = self._wall_plane(pl, regions == wi)
            if plane is not None:
                out.append((int(wi), plane))
        return out

    def _wall_extents(self, regions, labels, pl, min_frac: float, top: int):
        """``(region id, nrm, d, along, (s0, s1))`` of :meth:`_large_walls`: the horizontal
        along-wall axis and the extent of the wall's points along it (percentiles
        ``wall_extent_pct``, 100 − that) [m]."""
        pct = [self.thresholds.wall_extent_pct, 100 - self.thresholds.wall_extent_pct]
        out = []
        for wi, (nrm, d, _, wp) in self._large_walls(regions, labels, pl, min_frac, top):
            along = np.array([-nrm[1], nrm[0], 0.0])
            s0, s1 = np.percentile(wp @ along, pct)
            out.append((wi, nrm, d, along, (float(s0), float(s1))))
        return out

    def _wall_planes(self, regions, labels, pl) -> list[WallPlane]:
        """Planes of the large vertical ``wall`` regions (coplanar ones merged), with the
        along-wall extent of their pixels widened by ``facade_wall_pad_m`` (a door may split
        its wall).

        Regions within ``facade_coplanar_deg`` and ``facade_coplanar_m`` of each other are one
        wall; its face is the front-most of them
        (the largest offset: normals face the camera). A closed leaf is recessed a few
        centimetres behind its wall's face and a double door's leaves can outnumber the wall
        pixels around them: on the leaves' plane the frame around them lies in front of it
        (occluded cells) and the facade search would not see its posts."""
        cfg = self.thresholds
        pad = cfg.facade_wall_pad_m
        cos_c = math.cos(math.radians(cfg.facade_coplanar_deg))
        planes: list[WallPlane] = []
        for _, nrm, d, _, (s0, s1) in self._wall_extents(regions, labels, pl,
                                                         cfg.facade_wall_min_frac,
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

    def _facade_doors(self, regions, labels, scores, pl, rot, k, rgb, floor_z, ceil_z):
        """Doorways found by their frames on the rectified wall planes
        (:mod:`sim2radar.reconstruct.facade`); their pixels become ``door`` segments."""
        sigma = self.thresholds.facade_blur_sigma_px
        lab = cv2.cvtColor(cv2.GaussianBlur(rgb, (0, 0), sigma).astype(np.float32) / 255.0,
                           cv2.COLOR_RGB2LAB)[..., 0]
        grad = (cv2.Sobel(lab, cv2.CV_32F, 1, 0, ksize=3) / 8.0,
                cv2.Sobel(lab, cv2.CV_32F, 0, 1, ksize=3) / 8.0)
        boxes: list[list[float]] = []
        labels, scores = list(labels), list(scores)
        regions = regions.copy()
        self.last_facade = []
        for plane in self._wall_planes(regions, labels, pl):
            for door in find_facade_doors(plane, floor_z, ceil_z, rot, k, pl, grad,
                                          self.facade_config):
                self.last_facade.append(door)
                boxes.append([float(x) for x in door.box_level])
                m = door.mask & (regions >= 0)
                keep = np.isin(regions, [i for i, lbl in enumerate(labels)
                                         if lbl in ("wall", "clutter", "window", "door")])
                m &= keep
                if m.sum() >= self.thresholds.min_segment_px:
                    regions[m] = len(labels)
                    labels.append("door")
                    scores.append(0.6 + 0.3 * door.score)
        return regions, labels, scores, boxes

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
