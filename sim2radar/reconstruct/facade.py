"""Doors found on rectified wall planes ("facades"): the door frame's two posts and lintel.

A doorway in a wall is a door frame: two vertical posts standing on the floor, 0.9–2 m apart,
joined by a horizontal lintel at door height (2.0–2.3 m). Whatever the leaf's colour, material
or swing, the frame's outline is an image edge, and on the wall plane it is an upright
rectangle. Seen in the image at a grazing angle the same rectangle is a thin perspective
trapezoid that region segmentation of blurred, LiDAR-completed depth breaks into strips — so
the search runs on the wall plane instead (facade parsing, cf. Teboul et al., CVPR 2010).

For each wall plane ``n·p = d`` (level frame: x forward, y left, z up; ``n`` horizontal,
facing the camera):

1. A raster of cells ``cell_m`` apart spans the wall (``s`` along it, ``z`` from the floor up).
   Each cell's centre projects into the image through the intrinsics; cells outside the image
   or behind the camera are unseen. A cell is **on the plane** when the depth at its pixel puts
   the surface within ``plane_tol_m`` (+ 1 % of range) of the plane, **behind** when the surface
   lies farther (a recessed leaf, an open doorway), **occluded** when nearer (clutter, another
   wall).
2. Edge strengths are measured in the image at native resolution (Sobel on CIE L*) and
   projected on the wall's axes at each cell: the *vertical-edge* strength is the gradient
   component across the image direction of the wall's vertical, the *horizontal-edge* strength
   the component across the image direction of the wall's horizontal. Both are therefore
   resolution-independent and valid at any viewing angle.
3. A column ``s`` is a **post** candidate when strong vertical edges cover most of its seen
   cells from near the floor up to door height, and few above (tile grout and panel joints run
   on to the ceiling; a door frame stops at its lintel). Pairs of posts ``door_width_m`` apart
   with a lintel row (strong horizontal edges along most of the span at ``top_m``) are door
   hypotheses, scored by post and lintel coverage and chosen greedily without overlap.
   Behind-the-plane cells between the posts (recess or opening) add evidence. The joint where
   a double door's two leaves meet is an edge like a post: two leaf hypotheses sharing it
   are one double doorway (:func:`_double_doors`).
4. A doorway cut by the left or right image border shows one post only: a post whose lintel
   runs from it to the border, and not past it on its other side, is a doorway of
   ``nominal_width_m`` (scored below a pair, so a two-post doorway wins an overlap).

Returns doorway boxes ``x y z dx dy dz heading`` in the level frame (``dx`` along the wall, the
box spanning ``thickness_m`` behind the wall face, measured around the doorway: the plane searched
may be that of recessed leaves, :func:`_wall_face`) and the image pixels of each doorway.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from sim2radar.boxes import DOOR_THICKNESS_M, wrap_heading
from sim2radar.camera import project

__all__ = ["FacadeConfig", "FacadeDoor", "WallPlane", "find_facade_doors", "wall_raster"]


@dataclasses.dataclass(frozen=True)
class FacadeConfig:
    """Options of the facade door search.

    Attributes
    ----------
    cell_m : float [m] — raster cell size on the wall plane.
    door_width_m : (float, float) [m] — doorway width (outer frame edges), single to double. The
        lower bound is the narrowest clear opening (0.80 m in the procedural worlds) less 2 cm:
        a frame painted like its wall shows only its inner edges, against the leaf.
    top_m : (float, float) [m] — lintel height above the floor (doorway top).
    plane_tol_m : float [m] — surface within this of the plane counts as on it (+1 % of range).
    edge_min : float — absolute floor of the edge threshold [L* per pixel].
    edge_rel : float — the edge threshold is at least this × the median strength on the wall.
    post_cover : float — fraction of a post's seen cells (floor to lintel) with a vertical edge.
    above_cover_max : float — a post's edge coverage above the lintel must stay below this.
    lintel_cover : float — fraction of the span's seen lintel cells with a horizontal edge.
    min_seen : float — fraction of the doorway's cells that must be seen (on or behind the plane).
    thickness_m : float [m] — doorway box depth behind the wall face
        (:data:`sim2radar.boxes.DOOR_THICKNESS_M`).
    face_band_m : float [m] — the wall face is measured on the cells up to this far beside the
        doorway and above its lintel (:func:`_wall_face`).
    nominal_top_m : float [m] — doorway top assumed when the lintel is out of view (above the
        image; procedural worlds: 2.06–2.26 m).
    min_post_seen_m : float [m] — with the lintel out of view, both posts must be seen at least
        this high.
    border_doors : bool — also look for doorways cut by the left or right image border (one
        post and a lintel that runs from it to the border).
    nominal_width_m : float [m] — width given to such a doorway when less of it is seen
        (procedural worlds: single doors 0.92–1.12 m between the frame's outer edges).
    """

    cell_m: float = 0.02
    door_width_m: tuple[float, float] = (0.78, 2.0)
    top_m: tuple[float, float] = (1.95, 2.35)
    plane_tol_m: float = 0.06
    edge_min: float = 2.0
    edge_rel: float = 3.0
    post_cover: float = 0.55
    above_cover_max: float = 0.45
    lintel_cover: float = 0.45
    min_seen: float = 0.5
    thickness_m: float = DOOR_THICKNESS_M
    face_band_m: float = 0.4
    nominal_top_m: float = 2.16
    min_post_seen_m: float = 1.3
    border_doors: bool = True
    nominal_width_m: float = 1.0


@dataclasses.dataclass(frozen=True)
class WallPlane:
    """A vertical wall plane in the level frame: ``normal · p = offset_m`` (normal horizontal,
    facing the camera, so ``offset_m`` < 0), seen between ``s_range_m`` along
    ``(-normal_y, normal_x, 0)``."""

    normal: np.ndarray
    offset_m: float
    s_range_m: tuple[float, float]

    @property
    def along(self) -> np.ndarray:
        return np.array([-self.normal[1], self.normal[0], 0.0])


@dataclasses.dataclass(frozen=True)
class FacadeDoor:
    """A doorway found on a wall plane.

    Attributes
    ----------
    box_level : (7,) float64 — ``x y z dx dy dz heading`` in the level frame [m, rad].
    s_m : (float, float) [m] — the frame's outer edges along the wall (the doorway's ends).
    top_m : float [m] — doorway top (lintel) height above the floor.
    score : float — mean of post and lintel coverage, in [0, 1].
    mask : (H, W) bool — image pixels of the doorway (seen, not occluded).
    """

    box_level: np.ndarray
    s_m: tuple[float, float]
    top_m: float
    score: float
    mask: np.ndarray


@dataclasses.dataclass
class _Raster:
    s: np.ndarray  # (ns,) [m]
    z: np.ndarray  # (nz,) [m] above the floor
    uv: np.ndarray  # (nz, ns, 2) pixel coordinates
    seen: np.ndarray  # (nz, ns) bool: inside the image, in front of the camera
    state: np.ndarray  # (nz, ns) int8: 0 unseen/no depth, 1 on plane, 2 behind, 3 occluded
    behind: np.ndarray  # (nz, ns) how far the surface seen at each cell lies behind the plane [m]
    vedge: np.ndarray  # (nz, ns) vertical-edge strength [L*/px]
    hedge: np.ndarray  # (nz, ns) horizontal-edge strength [L*/px]


def _project(p_level: np.ndarray, cam_from_level: np.ndarray, k) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (…, 2) of level-frame points and their camera z (…)."""
    pc = p_level @ cam_from_level.T
    uv, _ = project(pc, k)
    return uv.reshape(*pc.shape[:-1], 2), pc[..., 2]


def wall_raster(plane: WallPlane, floor_z: float, height_m: float, level_rot: np.ndarray, k,
                points_level: np.ndarray, grad: tuple[np.ndarray, np.ndarray],
                config: FacadeConfig = FacadeConfig()) -> _Raster:
    """Sample depth state and oriented edge strengths on a raster of the wall plane.

    ``level_rot`` (3, 3) rotates camera to level coordinates; ``points_level`` (H, W, 3) are
    the back-projected pixels in the level frame; ``grad`` the image gradients (gx, gy) of L*.
    """
    c = config.cell_m
    s0, s1 = plane.s_range_m
    s = np.arange(s0, s1 + c / 2, c)
    z = np.arange(c / 2, height_m, c)
    n, a = np.asarray(plane.normal, np.float64), plane.along
    ez = np.array([0.0, 0.0, 1.0])
    base = plane.offset_m * n + floor_z * ez
    p = base + s[None, :, None] * a + z[:, None, None] * ez  # (nz, ns, 3)
    cam_from_level = np.asarray(level_rot, np.float64).T
    uv, zc = _project(p, cam_from_level, k)
    uv_z, _ = _project(p + 0.01 * ez, cam_from_level, k)
    uv_s, _ = _project(p + 0.01 * a, cam_from_level, k)
    h, w = points_level.shape[:2]
    seen = (zc > 0.1) & np.isfinite(uv).all(-1)
    seen &= (uv[..., 0] >= 0) & (uv[..., 0] <= w - 1) & (uv[..., 1] >= 0) & (uv[..., 1] <= h - 1)
    ui = np.clip(np.nan_to_num(uv[..., 0]).round().astype(np.int64), 0, w - 1)
    vi = np.clip(np.nan_to_num(uv[..., 1]).round().astype(np.int64), 0, h - 1)
    q = points_level[vi, ui]
    with np.errstate(invalid="ignore"):
        behind = plane.offset_m - q @ n  # > 0: the surface lies behind the plane
        rng = np.linalg.norm(p, axis=-1)
        tol = config.plane_tol_m + 0.01 * rng
        has = seen & np.isfinite(behind)
        state = np.zeros(seen.shape, np.int8)
        state[has & (np.abs(behind) <= tol)] = 1
        state[has & (behind > tol)] = 2
        state[has & (behind < -tol)] = 3
    gx, gy = grad
    gxs = cv2.remap(gx, uv[..., 0].astype(np.float32), uv[..., 1].astype(np.float32),
                    cv2.INTER_LINEAR, borderValue=0)
    gys = cv2.remap(gy, uv[..., 0].astype(np.float32), uv[..., 1].astype(np.float32),
                    cv2.INTER_LINEAR, borderValue=0)

    def across(d):  # gradient component across the image direction d (an edge along d)
        nrm = np.linalg.norm(d, axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.abs(gxs * (-d[..., 1]) + gys * d[..., 0]) / nrm

    vedge = np.nan_to_num(across(uv_z - uv)) * seen
    hedge = np.nan_to_num(across(uv_s - uv)) * seen
    return _Raster(s, z, uv, seen, state, np.where(has, behind, np.nan), vedge, hedge)


def _runs_cover(flags: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Fraction of valid cells flagged, per column (…, ns)."""
    nv = valid.sum(0)
    return np.where(nv > 0, (flags & valid).sum(0) / np.maximum(nv, 1), 0.0)


def find_facade_doors(plane: WallPlane, floor_z: float, ceil_z: float, level_rot: np.ndarray,
                      k, points_level: np.ndarray, grad: tuple[np.ndarray, np.ndarray],
                      config: FacadeConfig = FacadeConfig()) -> list[FacadeDoor]:
    """Doorways on one wall plane (see the module docstring)."""
    c = config.cell_m
    height = float(min(ceil_z - floor_z, config.top_m[1] + 0.6)) if math.isfinite(ceil_z) \
        else config.top_m[1] + 0.6
    r = wall_raster(plane, floor_z, height, level_rot, k, points_level, grad, config)
    on = r.state == 1
    visible = (r.state == 1) | (r.state == 2)
    if on.sum() < 50:
        return []
    thr_v = max(config.edge_min, config.edge_rel * float(np.median(r.vedge[on])))
    thr_h = max(config.edge_min, config.edge_rel * float(np.median(r.hedge[on])))
    # an edge may fall between cells or be smeared over a few at grazing angles: max over ±2
    ve = cv2.dilate((r.vedge > thr_v).astype(np.uint8), np.ones((1, 5), np.uint8)).astype(bool)
    he = cv2.dilate((r.hedge > thr_h).astype(np.uint8), np.ones((5, 1), np.uint8)).astype(bool)
    iz = lambda zz: int(np.clip(round(zz / c), 0, len(r.z)))  # noqa: E731
    lo_z, hi_z = iz(0.25), iz(config.top_m[0] - 0.1)
    post = _runs_cover(ve[lo_z:hi_z], visible[lo_z:hi_z])
    n_seen = visible[lo_z:hi_z].sum(0)
    post[n_seen < 0.5 * (hi_z - lo_z)] = 0.0
    above_lo, above_hi = iz(config.top_m[1] + 0.1), len(r.z)
    if above_hi - above_lo >= 5:
        above = _runs_cover(ve[above_lo:above_hi], on[above_lo:above_hi])
        post[above > config.above_cover_max] = 0.0
    # posts: runs of columns with enough coverage (a frame's two edges, widened by the ±2-cell
    # dilation, make one run); a run's outer ends, less the dilation, are the frame's edges
    runs = _runs(post >= config.post_cover)
    pairs: dict[tuple[int, int], tuple[float, int, int, int]] = {}
    wmin, wmax = (int(round(x / c)) for x in config.door_width_m)
    tz = range(iz(config.top_m[0]), min(iz(config.top_m[1]), len(r.z) - 1) + 1)
    if not tz:
        # the raster (floor to ceiling) ends below the lowest lintel: no doorway of door height
        return []
    for ia, (a0, a1) in enumerate(runs):
        for ib, (b0, b1) in enumerate(runs[ia + 1:], start=ia + 1):
            ja, jb = min(a0 + 2, a1), max(b1 - 2, b0)  # outer frame edges
            if jb - ja < wmin:
                continue
            if jb - ja > wmax:
                break
            span = slice(a1 + 1, b0)
            if span.stop - span.start < 3:
                continue
            best = _lintel(he, visible, span, tz)
            if best[1] < 0:
                # the lintel is out of view (above the image): posts seen up to the image edge
                # with door height assumed, when they are seen at least ``min_post_seen_m`` high
                top_seen = visible[:, [ja, jb]].all(1)
                seen_h = c * np.flatnonzero(top_seen).max() if top_seen.any() else 0.0
                t_nom = iz(config.nominal_top_m)
                if t_nom >= len(r.z):  # a room lower than a door: no doorway of that height
                    continue
                if seen_h < config.min_post_seen_m or r.seen[t_nom, ja:jb].any():
                    continue
                best = (0.5 * config.lintel_cover, t_nom)
            elif best[0] < config.lintel_cover:
                continue
            t = best[1]
            inside = visible[:t, ja:jb + 1]
            if inside.mean() < config.min_seen:
                continue
            score = (post[a0:a1 + 1].max() + post[b0:b1 + 1].max() + best[0]) / 3.0
            pairs[(ia, ib)] = (score, int(ja), int(jb), int(t))
    doors = list(pairs.values()) + _double_doors(pairs, wmax, int(round(0.1 / c)))
    if config.border_doors:
        doors += _border_doors(r, runs, post, he, visible, tz, config)
    doors.sort(reverse=True)
    chosen: list[tuple[float, int, int, int]] = []
    for d in doors:
        if all(d[2] < e[1] - 2 or d[1] > e[2] + 2 for e in chosen):
            chosen.append(d)
    out = []
    h, w = points_level.shape[:2]
    n = np.asarray(plane.normal, np.float64)
    a = plane.along
    heading = float(wrap_heading(math.atan2(a[1], a[0])))
    for score, ja, jb, t in chosen:
        # a doorway cut by the image border runs past the raster's last seen column
        sa, sb = r.s[0] + c * ja, r.s[0] + c * jb
        ja, jb = max(ja, 0), min(jb, len(r.s) - 1)
        top = float(r.z[t] + c / 2)
        th = config.thickness_m
        face = plane.offset_m + _wall_face(r, ja, jb, t, config)
        cxy = 0.5 * (sa + sb) * a[:2] + (face - th / 2) * n[:2]
        box = np.array([cxy[0], cxy[1], floor_z + top / 2, sb - sa, th, top, heading])
        cells = np.zeros(r.seen.shape, bool)
        cells[:t + 1, ja:jb + 1] = True
        cells &= (r.state == 1) | (r.state == 2)
        mask = np.zeros((h, w), np.uint8)
        uv = r.uv[cells]
        if len(uv):
            poly = cv2.convexHull(uv.astype(np.float32)).astype(np.int32)
            cv2.fillConvexPoly(mask, poly, 1)
        out.append(FacadeDoor(box, (float(sa), float(sb)), top, float(score), mask.astype(bool)))
    return out


def _double_doors(pairs: dict[tuple[int, int], tuple[float, int, int, int]], wmax: int,
                  top_tol: int) -> list[tuple[float, int, int, int]]:
    """Double doors: two leaves meeting at a joint. The joint is an edge from the floor to the
    lintel like a post, so each leaf is a doorway hypothesis of its own between a frame post
    and the joint, and the greedy choice would keep one leaf (half the doorway). Two leaf
    hypotheses sharing the joint's run (no other post between them), of similar width (ratio
    ≤ 1.5) and top (within ``top_tol`` cells), and together at most ``wmax`` cells wide are one
    doorway, scored above either leaf so that it wins the overlap. Two single doors side by
    side do not share a post: each has its own frame, with wall between them.

    ``pairs`` maps (left run, right run) to ``(score, first cell, last cell, top row)``."""
    out = []
    for (ia, im), left in pairs.items():
        right = pairs.get((im, im + 1))
        if right is None or im != ia + 1:
            continue
        wl, wr = left[2] - left[1], right[2] - right[1]
        if (max(wl, wr) > 1.5 * min(wl, wr) or abs(left[3] - right[3]) > top_tol
                or right[2] - left[1] > wmax):
            continue
        whole = pairs.get((ia, im + 1))
        top = whole[3] if whole is not None else max(left[3], right[3])
        score = max(left[0], right[0], whole[0] if whole is not None else 0.0) + 0.05
        out.append((score, left[1], right[2], top))
    return out


def _lintel(he: np.ndarray, visible: np.ndarray, span: slice, tz: range) -> tuple[float, int]:
    """Best lintel row over the columns ``span``: ``(coverage, row)`` — the fraction of the
    seen columns with a horizontal edge in rows ``row`` ± 1, for the rows ``tz`` where at least
    half the span is seen; ``(0.0, -1)`` when no row in ``tz`` is (the lintel out of view)."""
    covs = np.full(len(tz), -1.0)
    for i, t in enumerate(tz):
        rows = slice(max(0, t - 1), t + 2)
        vis = visible[rows, span].any(0)
        if vis.sum() >= 0.5 * (span.stop - span.start):
            covs[i] = float((he[rows, span].any(0) & vis).sum() / max(vis.sum(), 1))
    if covs.max() < 0:
        return 0.0, -1
    # the lintel's edges, dilated, make a plateau of rows: its centre is the top
    near = np.flatnonzero(covs >= 0.9 * covs.max())
    return float(covs.max()), tz[int(round(near.mean()))]


def _border_doors(r: _Raster, runs: list[tuple[int, int]], post: np.ndarray, he: np.ndarray,
                  visible: np.ndarray, tz: range,
                  config: FacadeConfig) -> list[tuple[float, int, int, int]]:
    """Doorways cut by the left or right image border: one post, and a lintel from it to
    the border (see :func:`find_facade_doors`).

    The wall beyond the last seen column is out of the image, so the second post is not
    seen; the doorway is ``nominal_width_m`` wide (or reaches 0.1 m past the border when more
    than that is seen). The lintel edge must cover the seen span and must stop at the post (a
    line that runs on past it — a dado rail, a cabinet top — is no lintel). Scored below a
    two-post doorway of the same coverage, so a found pair wins an overlap."""
    c = config.cell_m
    nz, ns = visible.shape
    iz = lambda zz: int(np.clip(round(zz / c), 0, nz))  # noqa: E731
    lo_z, hi_z = iz(0.25), iz(config.top_m[0] - 0.1)
    in_image = r.seen[lo_z:hi_z].mean(0) > 0.5
    wmin, wmax = (int(round(x / c)) for x in config.door_width_m)
    nominal = int(round(config.nominal_width_m / c))
    out = []
    for k, (a0, a1) in enumerate(runs):
        for side in (+1, -1):
            j_post = min(a0 + 2, a1) if side > 0 else max(a1 - 2, a0)  # the frame's outer edge
            start = a1 + 1 if side > 0 else a0 - 1
            if not (0 <= start < ns) or not in_image[start]:
                continue
            # the seen span from the post to the image border
            step = np.arange(start, ns) if side > 0 else np.arange(start, -1, -1)
            off = np.flatnonzero(~in_image[step])
            if not len(off):
                continue
            j_end = int(step[off[0] - 1]) if off[0] > 0 else start
            if side > 0 and any(b0 <= j_end for b0, _ in runs[k + 1:]):
                continue  # another post before the border: a pair, or no door
            if side < 0 and any(b1 >= j_end for _, b1 in runs[:k]):
                continue
            lo, hi = sorted((start, j_end))
            seen_w = abs(j_end - j_post)
            if hi - lo < 10 or seen_w > wmax:
                continue
            span = slice(lo, hi + 1)
            if visible[:iz(config.top_m[0]), span].mean() < config.min_seen:
                continue
            cover, t = _lintel(he, visible, span, tz)
            if cover < config.lintel_cover:
                continue
            # the lintel stops at the post: little horizontal edge 4–30 cm outside it
            rows = slice(max(0, t - 1), t + 2)
            o0, o1 = (j_post - 15, j_post - 2) if side > 0 else (j_post + 3, j_post + 16)
            o0, o1 = max(0, o0), min(ns, o1)
            vis_out = visible[rows, o0:o1].any(0)
            if vis_out.sum() < 5 or (he[rows, o0:o1].any(0) & vis_out).mean() > 0.3:
                continue
            width = max(nominal, seen_w + int(round(0.1 / c)), wmin)
            ja, jb = (j_post, j_post + width) if side > 0 else (j_post - width, j_post)
            score = 0.8 * (post[a0:a1 + 1].max() + cover) / 2.0
            out.append((float(score), int(ja), int(jb), int(t)))
    return out


def _wall_face(r: _Raster, ja: int, jb: int, t: int, config: FacadeConfig) -> float:
    """Offset [m] (towards the camera) of the wall face around a doorway from the plane it was
    found on; 0 when the plane is the face.

    The plane searched may be that of the closed leaves, recessed by up to the wall thickness
    less the leaf (5–10 cm): a leaf region too far behind the wall to merge with it, or a wall
    region too small to be a plane of its own. The frame's outline is seen on either plane,
    but the doorway box spans the wall from its face. The face is measured where little stands
    in front of a wall: on the wall over the doorway (cells from 6 cm to ``face_band_m`` above
    the lintel: the median of the surfaces within 25 cm of the plane, when 30 cells are seen and
    the wall beside the frame does not lie on the other side of the plane), else beside the
    frame from 1.2 m up (above handrails and most cabinets: the median of the surfaces 2–25 cm
    in front of the plane, when they are at least 40 % of the cells seen there and 20 cells)."""
    c = config.cell_m
    nz, ns = r.state.shape
    band = int(round(config.face_band_m / c))

    def near(rows: slice, cols: slice) -> np.ndarray:
        b = r.behind[rows, cols].ravel()
        return b[np.isfinite(b) & (np.abs(b) < 0.25)]

    rows = slice(int(round(1.2 / c)), t)
    side = np.concatenate([near(rows, slice(max(0, ja - band), max(0, ja - 1))),
                           near(rows, slice(min(ns, jb + 2), min(ns, jb + band)))])
    above = near(slice(min(nz, t + 3), min(nz, t + band)), slice(max(0, ja), min(ns, jb + 1)))
    if len(above) >= 30:
        med = float(np.median(above))
        beside = float(np.median(side)) if len(side) >= 20 else 0.0
        if beside * med < 0 and abs(beside) > 0.02:
            return 0.0  # the wall beside the frame disagrees (a bulkhead or sign over the door)
        return -med if abs(med) > 0.02 else 0.0
    front = side[side < -0.02]
    if len(front) < 20 or len(front) < 0.4 * len(side):
        return 0.0
    return float(-np.median(front))


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) indices of the runs of True in a 1-D bool array, in order."""
    f = np.concatenate([[False], flags.astype(bool), [False]])
    d = np.diff(f.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1).tolist(), (np.flatnonzero(d == -1) - 1).tolist(),
                    strict=True))
