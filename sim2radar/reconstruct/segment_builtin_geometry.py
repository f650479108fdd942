"""Region geometry and label-map primitives of the ``builtin`` segmenter.

Pure functions over arrays, used by the step functions of
:mod:`sim2radar.reconstruct.segment_builtin`: the shape of one region in the
level frame (:class:`SegmentGeometry`, :func:`region_geometry`: plane fit, extents, fill, the
image borders it reaches), and operations on a label map (an (H, W) int array, -1 unlabelled):
:func:`fill_nearest`, :func:`fill_columns` and the :class:`UnionFind` the region merge uses.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from sim2radar.reconstruct.backproject import finite_rows

__all__ = ["SegmentGeometry", "UnionFind", "fill_columns", "fill_nearest", "footprint_gap_m",
           "region_geometry", "row_ends"]


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
    pts = pts[finite_rows(pts)].astype(np.float64)
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
    n_px = int(mask.sum())
    if n_px >= 3:
        hull = cv2.convexHull(row_ends(mask))
        fill = min(1.0, n_px / max(cv2.contourArea(hull) + 0.5 * cv2.arcLength(hull, True) + 1, 1))
    else:
        fill = 0.0
    return SegmentGeometry(n_px, c, n, planarity, float(a1 - a0), float(z0), float(z1),
                           float(fill), touches)


def row_ends(mask: np.ndarray) -> np.ndarray:
    """(2 k, 2) int32 (x, y) — the first and last pixel of each of the ``k`` rows of ``mask``
    that have one. Every pixel of a row lies between its two ends, so these have the same
    convex hull as all the pixels, at a 20th of the cost of listing them (``cv2.convexHull``
    gives the same vertices: tested against the full pixel list)."""
    rows = np.flatnonzero(mask.any(axis=1))
    sub = mask[rows]
    ends = np.empty((2 * len(rows), 2), np.int32)
    ends[0::2, 0] = np.argmax(sub, axis=1)
    ends[1::2, 0] = mask.shape[1] - 1 - np.argmax(sub[:, ::-1], axis=1)
    ends[0::2, 1] = ends[1::2, 1] = rows
    return ends


def fill_columns(labels: np.ndarray) -> np.ndarray:
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


class UnionFind:
    """Disjoint sets over ``0 .. n-1`` (path halving; the smaller id is the root)."""

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


def fill_nearest(labels: np.ndarray, fillable: np.ndarray) -> np.ndarray:
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
