"""Doors found by their frames on rectified wall planes (``reconstruct.facade``).

The scenes are ray-cast analytically in NumPy: a level camera 1.4 m above the floor (ceiling
2.7 m above it), vertical walls painted in CIE L*, and a door frame (two 6 cm posts from the
floor to a 6 cm lintel whose top is at 2.1 m) 25 L* darker than the wall. The per-pixel
level-frame points are the ray–surface intersections; the image gradients are computed as
``segment_builtin_doors.facade_doors`` computes them (Gaussian σ 0.8, L*, Sobel / 8).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import cv2
import numpy as np
import pytest

from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct.backproject import level_from_camera
from sim2radar.reconstruct.facade import FacadeConfig, WallPlane, find_facade_doors, wall_raster

FLOOR_Z, CEIL_Z = -1.4, 1.3  # level frame, camera at the origin: 1.4 m high, 2.7 m room
ROT = level_from_camera(np.array([0.0, -1.0, 0.0]))[:3, :3]  # level camera: camera → level
K_FRONT = CameraIntrinsics.from_fov(640, 480, 70.0)
K_WIDE = CameraIntrinsics.from_fov(640, 480, 90.0)
WALL_L, FRAME_L = 70.0, 45.0
POST_M, TOP_M = 0.06, 2.1

# a wall 4 m ahead facing the camera (s runs to the image's right) ...
FRONT = WallPlane(np.array([-1.0, 0.0, 0.0]), -4.0, (-3.0, 3.0))
# ... and a side wall 1.5 m to the left (s runs forward), seen at 49°–61° incidence across
# the doorway at s = 1.7–2.7 m
SIDE = WallPlane(np.array([0.0, -1.0, 0.0]), -1.5, (0.5, 5.0))
CASES = {"front": (FRONT, K_FRONT, (-0.5, 0.5)), "oblique": (SIDE, K_WIDE, (1.7, 2.7))}


# -- analytic scene ---------------------------------------------------------------------------


def _rays_level(k: CameraIntrinsics, ss: int) -> np.ndarray:
    """Level-frame viewing rays (camera z = 1) through ``ss × ss`` sub-pixels of each pixel."""
    o = (np.arange(ss) + 0.5) / ss
    u = (np.arange(k.width)[:, None] + o).ravel()
    v = (np.arange(k.height)[:, None] + o).ravel()
    uu, vv = np.meshgrid(u, v)
    rc = np.stack([(uu - k.cx) / k.fx, (vv - k.cy) / k.fy, np.ones_like(uu)], -1)
    return rc @ ROT.T


def _trace(rays: np.ndarray, surfaces) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit per ray. ``surfaces``: (normal, offset, paint(s, h) → L* or NaN where the
    surface is absent), ``s`` along ``(-n_y, n_x, 0)`` and ``h`` the height above the floor."""
    best = np.full(rays.shape[:2], np.inf)
    lum = np.full(rays.shape[:2], np.nan)
    for n, d, paint in surfaces:
        n = np.asarray(n, np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = d / (rays @ n)
        p = rays * np.where(np.isfinite(t), t, 0)[..., None]
        val = paint(p @ np.array([-n[1], n[0], 0.0]), p[..., 2] - FLOOR_Z)
        hit = (t > 0) & (t < best) & np.isfinite(val)
        best = np.where(hit, t, best)
        lum = np.where(hit, val, lum)
    return best, lum


def _const(value):
    return lambda s, h: np.full(s.shape, value)


def _render(k: CameraIntrinsics, walls, ss: int = 2):
    """L* image (``ss²`` supersampled) and level-frame points (H, W, 3) of a room: floor,
    ceiling and the given walls."""
    surfaces = [((0, 0, 1.0), FLOOR_Z, _const(50.0)), ((0, 0, 1.0), CEIL_Z, _const(85.0)), *walls]
    _, lum = _trace(_rays_level(k, ss), surfaces)
    lum = lum.reshape(k.height, ss, k.width, ss).mean((1, 3))
    rays = _rays_level(k, 1)
    t, _ = _trace(rays, surfaces)
    return lum, (rays * t[..., None]).astype(np.float32)


def _grad(lum: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grey sRGB image of the L* values, then the gradients as the segmenter measures them."""
    y = np.where(lum > 8, ((lum + 16) / 116) ** 3, lum / 903.3)
    srgb = np.where(y <= 0.0031308, 12.92 * y, 1.055 * y ** (1 / 2.4) - 0.055)
    rgb = np.repeat(np.clip(np.round(srgb * 255), 0, 255).astype(np.uint8)[..., None], 3, -1)
    lab = cv2.cvtColor(cv2.GaussianBlur(rgb, (0, 0), 0.8).astype(np.float32) / 255.0,
                       cv2.COLOR_RGB2LAB)[..., 0]
    return (cv2.Sobel(lab, cv2.CV_32F, 1, 0, ksize=3) / 8.0,
            cv2.Sobel(lab, cv2.CV_32F, 0, 1, ksize=3) / 8.0)


def _frame(sa: float, sb: float, top: float = TOP_M, lintel: bool = True):
    """Wall paint with a door frame whose outer edges are at ``sa``, ``sb`` and ``top``."""

    def paint(s, h):
        post = ((s >= sa) & (s <= sa + POST_M)) | ((s >= sb - POST_M) & (s <= sb))
        dark = post & (h >= 0) & (h <= top)
        if lintel:
            dark |= (s >= sa) & (s <= sb) & (h >= top - POST_M) & (h <= top)
        return np.where(dark, FRAME_L, WALL_L)

    return paint


def _wall(plane: WallPlane, paint):
    return (plane.normal, plane.offset_m, paint)


def _scene_walls(plane: WallPlane, paint):
    """The painted wall, plus (for the side wall) a plain end wall 6 m ahead for the rays that
    miss it."""
    walls = [_wall(plane, paint)]
    if plane is SIDE:
        walls.append(((-1.0, 0.0, 0.0), -6.0, _const(64.0)))
    return walls


@functools.cache
def _door_scene(case: str):
    plane, k, (sa, sb) = CASES[case]
    lum, pts = _render(k, _scene_walls(plane, _frame(sa, sb)))
    return plane, k, (sa, sb), pts, _grad(lum)


def _doors(plane, k, pts, grad, config=FacadeConfig()):
    return find_facade_doors(plane, FLOOR_Z, CEIL_Z, ROT, k, pts, grad, config)


def _project(p_level: np.ndarray, k: CameraIntrinsics) -> np.ndarray:
    pc = np.asarray(p_level, np.float64) @ ROT  # level → camera (ROT is orthonormal)
    return np.stack([k.fx * pc[..., 0] / pc[..., 2] + k.cx,
                     k.fy * pc[..., 1] / pc[..., 2] + k.cy], -1)


# -- doors found ------------------------------------------------------------------------------


@pytest.mark.parametrize("case", ["front", "oblique"])
def test_door_frame_is_found_once_with_its_width_top_heading_and_depth(case):
    """A 1.0 m wide frame topped at 2.1 m is one doorway, seen head-on at 4 m or at 49°–61°
    incidence on a side wall: its width within 10 cm, its top within 8 cm (of the lintel's top
    edge), its outer frame edges within 6 cm of the true ones, its box turned along the wall, standing on the floor and spanning ``thickness_m``
    behind the wall face (centre half of it behind)."""
    plane, k, (sa, sb), pts, grad = _door_scene(case)
    cfg = FacadeConfig()
    doors = _doors(plane, k, pts, grad, cfg)
    assert len(doors) == 1
    door = doors[0]
    box = door.box_level
    assert box.shape == (7,)
    assert door.s_m[1] - door.s_m[0] == pytest.approx(sb - sa, abs=0.10)
    # the doorway's ends (outer frame edges) within 6 cm
    assert door.s_m[0] == pytest.approx(sa, abs=0.06)
    assert door.s_m[1] == pytest.approx(sb, abs=0.06)
    assert box[3] == pytest.approx(door.s_m[1] - door.s_m[0])
    assert box[3] == pytest.approx(sb - sa, abs=0.10)
    assert door.top_m == pytest.approx(TOP_M, abs=0.08)
    assert box[5] == pytest.approx(door.top_m)
    assert box[2] - box[5] / 2 == pytest.approx(FLOOR_Z, abs=1e-9)  # stands on the floor
    assert box[4] == pytest.approx(cfg.thickness_m)
    # heading: the box's dx axis runs along the wall (boxes are symmetric under π)
    assert abs(math.cos(box[6]) * plane.along[0] + math.sin(box[6]) * plane.along[1]) \
        == pytest.approx(1.0, abs=1e-9)
    # the centre lies thickness/2 behind the face (n · p = offset − thickness / 2), within
    # the found posts along the wall
    assert box[:2] @ plane.normal[:2] == pytest.approx(plane.offset_m - cfg.thickness_m / 2,
                                                       abs=1e-9)
    assert door.s_m[0] < box[:2] @ plane.along[:2] < door.s_m[1]
    assert 0.5 <= door.score <= 1.0


@pytest.mark.parametrize("case", ["front", "oblique"])
def test_door_mask_covers_the_doorway_pixels(case):
    """The doorway's image mask is the found wall rectangle (posts, floor to top) projected
    into the image (IoU > 0.95), and it overlaps the projection of the true outer frame with
    IoU > 0.85."""
    plane, k, (sa, sb), pts, grad = _door_scene(case)
    (door,) = _doors(plane, k, pts, grad)

    def iou(a, b, top):
        base = plane.offset_m * plane.normal + np.array([0.0, 0.0, FLOOR_Z])
        corners = [base + s * plane.along + np.array([0.0, 0.0, h])
                   for s, h in ((a, 0.0), (b, 0.0), (b, top), (a, top))]
        poly = np.zeros((k.height, k.width), np.uint8)
        cv2.fillConvexPoly(poly, np.round(_project(np.array(corners), k)).astype(np.int32), 1)
        poly = poly.astype(bool)
        return (door.mask & poly).sum() / (door.mask | poly).sum()

    assert iou(door.s_m[0], door.s_m[1], door.top_m) > 0.95
    assert iou(sa, sb, TOP_M) > 0.85


@pytest.mark.parametrize("case", ["front", "oblique"])
def test_door_posts_are_located_along_the_wall(case):
    """The doorway's ends lie within 4 cm of the outer frame edges and the box centre within
    3 cm of the doorway's centre along the wall (in the head-on view the scene is mirror-
    symmetric about s = 0, so the answer must be too: a plateau of equal post scores must not
    pull both ends one way)."""
    plane, k, (sa, sb), pts, grad = _door_scene(case)
    (door,) = _doors(plane, k, pts, grad)
    assert door.s_m[0] == pytest.approx(sa, abs=0.04)
    assert door.s_m[1] == pytest.approx(sb, abs=0.04)
    assert door.box_level[:2] @ plane.along[:2] == pytest.approx(0.5 * (sa + sb), abs=0.03)


@pytest.mark.parametrize("recess_m", [0.05, 0.10])
def test_door_found_on_its_recessed_leaf_plane_is_boxed_from_the_wall_face(recess_m):
    """A closed leaf recessed 5–10 cm behind the wall face (a 15 cm wall, the leaf on its far
    side) may be a wall region of its own, and the frame is found on its plane too. The
    doorway box still spans the wall from its face: its centre lies ``thickness_m``/2 behind
    the wall face (within 1.5 cm; 5–10 cm deeper without measuring the face over the lintel),
    as when the search runs on the wall plane itself."""
    sa, sb = -0.5, 0.5
    inner = _frame(sa, sb)

    def wall(s, h):  # the wall, open inside the frame
        return np.where((s > sa + POST_M) & (s < sb - POST_M) & (h < TOP_M - POST_M),
                        np.nan, inner(s, h))

    def leaf(s, h):
        return np.where((s > sa) & (s < sb) & (h < TOP_M), 55.0, np.nan)

    leaf_plane = WallPlane(FRONT.normal, FRONT.offset_m - recess_m, FRONT.s_range_m)
    lum, pts = _render(K_FRONT, [_wall(FRONT, wall), _wall(leaf_plane, leaf)])
    grad = _grad(lum)
    cfg = FacadeConfig()
    want = FRONT.offset_m - cfg.thickness_m / 2
    for plane in (leaf_plane, FRONT):
        (door,) = _doors(plane, K_FRONT, pts, grad, cfg)
        assert door.s_m == pytest.approx((sa, sb), abs=0.06)
        assert door.box_level[:2] @ FRONT.normal[:2] == pytest.approx(want, abs=0.015)


def test_door_cut_by_the_image_border_is_found_from_one_post_and_its_lintel():
    """A doorway at s = 2.3–3.3 m on the wall 4 m ahead leaves the image at s ≈ 2.8 m (70°
    field of view): one post and half the lintel are seen. It is found with its seen end within
    4 cm and its nominal width (``nominal_width_m``), running past the border; without the
    border hypothesis (``border_doors=False``) it is not."""
    lum, pts = _render(K_FRONT, [_wall(FRONT, _frame(2.3, 3.3))])
    grad = _grad(lum)
    half = 4.0 * math.tan(math.radians(35.0))
    assert 2.3 < half < 3.3 - 0.3
    cfg = FacadeConfig()
    (door,) = _doors(FRONT, K_FRONT, pts, grad, cfg)
    assert door.s_m[0] == pytest.approx(2.3, abs=0.04)
    assert door.s_m[1] - door.s_m[0] == pytest.approx(cfg.nominal_width_m, abs=0.03)
    assert door.s_m[1] > half
    assert door.top_m == pytest.approx(TOP_M, abs=0.08)
    assert door.mask.any()
    assert _doors(FRONT, K_FRONT, pts, grad,
                  dataclasses.replace(cfg, border_doors=False)) == []


def test_border_door_needs_a_lintel_that_stops_at_its_post():
    """The same post with a horizontal line at door height that runs along the whole wall (a
    rail, a paint line) is no doorway: a lintel stops at its posts."""

    def paint(s, h):
        post = (s >= 2.3) & (s <= 2.3 + POST_M) & (h >= 0) & (h <= TOP_M)
        rail = (h >= TOP_M - POST_M) & (h <= TOP_M)
        return np.where(post | rail, FRAME_L, WALL_L)

    lum, pts = _render(K_FRONT, [_wall(FRONT, paint)])
    assert _doors(FRONT, K_FRONT, pts, _grad(lum)) == []


# -- no door ----------------------------------------------------------------------------------


def test_plain_wall_has_no_door():
    """A uniform wall (its only edges the floor and ceiling lines) has no doorway."""
    lum, pts = _render(K_FRONT, [_wall(FRONT, _const(WALL_L))])
    assert _doors(FRONT, K_FRONT, pts, _grad(lum)) == []


def _double_frame(sa: float, sb: float, joint_l: float = 55.0):
    """A door frame from ``sa`` to ``sb`` holding two equal leaves that meet at a 1.5 cm dark
    joint in the middle, from the floor to the lintel."""
    frame = _frame(sa, sb)
    mid = 0.5 * (sa + sb)

    def paint(s, h):
        joint = (np.abs(s - mid) <= 0.0075) & (h >= 0) & (h <= TOP_M - POST_M)
        return np.where(joint, joint_l, frame(s, h))

    return paint


def test_double_door_is_one_doorway_not_one_of_its_leaves():
    """A 1.8 m double door whose leaves meet at a joint running from the floor to the lintel:
    the joint is an edge like a post, so each leaf is a doorway hypothesis — but the doorway is
    the whole frame (one box 1.8 m wide, within 10 cm), not one leaf. Two single doors side by
    side, each in its own frame with 0.3 m of wall between, stay two doorways."""
    lum, pts = _render(K_FRONT, [_wall(FRONT, _double_frame(-0.9, 0.9))])
    (door,) = _doors(FRONT, K_FRONT, pts, _grad(lum))
    assert door.s_m[0] == pytest.approx(-0.9, abs=0.06)
    assert door.s_m[1] == pytest.approx(0.9, abs=0.06)
    assert door.top_m == pytest.approx(TOP_M, abs=0.08)

    def two_singles(s, h):
        return np.minimum(_frame(-1.25, -0.25)(s, h), _frame(0.05, 1.05)(s, h))

    lum, pts = _render(K_FRONT, [_wall(FRONT, two_singles)])
    doors = sorted(_doors(FRONT, K_FRONT, pts, _grad(lum)), key=lambda d: d.s_m[0])
    assert len(doors) == 2
    assert [x for d in doors for x in d.s_m] == pytest.approx([-1.25, -0.25, 0.05, 1.05],
                                                               abs=0.06)


def _tiles(s, h):
    """Tiles 0.5 m wide and 0.3 m high: 2 cm grout lines at s = k·0.5 from the floor to the
    ceiling, and at h = k·0.3 (one at 2.1 m, door height)."""
    vert = np.abs(s / 0.5 - np.round(s / 0.5)) * 0.5 < 0.01
    hor = np.abs(h / 0.3 - np.round(h / 0.3)) * 0.3 < 0.01
    return np.where(vert | hor, FRAME_L, WALL_L)


def test_tile_grout_running_to_the_ceiling_is_no_door():
    """A tiled wall has vertical edges 1.0 and 1.5 m apart from the floor up and a horizontal
    grout line at 2.1 m — posts and a lintel — but its verticals run on above door height to
    the ceiling, which a door frame's posts do not: no door. (Control: with the above-lintel
    test disabled the same wall does yield doors, so that test is what rejects them.)"""
    lum, pts = _render(K_FRONT, [_wall(FRONT, _tiles)])
    grad = _grad(lum)
    assert _doors(FRONT, K_FRONT, pts, grad) == []
    loose = dataclasses.replace(FacadeConfig(), above_cover_max=1.01)
    assert len(_doors(FRONT, K_FRONT, pts, grad, loose)) >= 1


def test_posts_without_a_lintel_are_no_door():
    """Two 6 cm posts 1 m apart from the floor to 2.1 m but no lintel joining them (e.g. two
    pilasters, shelf uprights) are no doorway."""
    lum, pts = _render(K_FRONT, [_wall(FRONT, _frame(-0.5, 0.5, lintel=False))])
    assert _doors(FRONT, K_FRONT, pts, _grad(lum)) == []


def test_frame_narrower_than_a_door_is_no_door():
    """A complete frame only 0.5 m wide (below ``door_width_m[0]`` = 0.78 m: a cupboard, a
    service hatch) is no doorway. (Control: allowing 0.4 m wide doorways finds it.)"""
    cfg = FacadeConfig()
    assert 0.5 < cfg.door_width_m[0]
    lum, pts = _render(K_FRONT, [_wall(FRONT, _frame(-0.25, 0.25))])
    grad = _grad(lum)
    assert _doors(FRONT, K_FRONT, pts, grad, cfg) == []
    wide = dataclasses.replace(cfg, door_width_m=(0.4, cfg.door_width_m[1]))
    assert len(_doors(FRONT, K_FRONT, pts, grad, wide)) == 1


def test_frame_painted_like_its_wall_is_found_from_its_inner_edges():
    """A frame painted like the wall shows no outer edge: only its inner edges against a
    darker leaf, 0.80 m apart (the narrowest clear opening) under a lintel edge at 2.04 m. That
    is still one doorway, 0.80 m wide within 6 cm."""
    def paint(s, h):
        return np.where((np.abs(s) < 0.40) & (h < TOP_M - POST_M), FRAME_L, WALL_L)

    lum, pts = _render(K_FRONT, [_wall(FRONT, paint)])
    (door,) = _doors(FRONT, K_FRONT, pts, _grad(lum))
    assert door.s_m == pytest.approx((-0.40, 0.40), abs=0.06)
    assert door.top_m == pytest.approx(TOP_M - POST_M, abs=0.08)


def _wardrobe(s, h):
    """Front face of a 1.2 m wide, 2.0 m tall dark wardrobe 1 m in front of the wall."""
    return np.where((np.abs(s) <= 0.6) & (h >= 0) & (h <= 2.0), FRAME_L, np.nan)


def test_doorway_hidden_behind_an_occluder_is_no_door():
    """A wardrobe 3 m ahead hides the whole doorway. Its dark outline, projected on the wall
    4 m ahead, looks like a frame (sides 1.6 m apart from the floor up, top at 2.2 m) — but the
    depth puts those wall cells behind the wardrobe (occluded), so no door is found. (Control:
    the same image with the depth of a bare wall does yield a door.)"""
    walls = [_wall(FRONT, _frame(-0.5, 0.5)), ((-1.0, 0.0, 0.0), -3.0, _wardrobe)]
    lum, pts = _render(K_FRONT, walls)
    grad = _grad(lum)
    assert _doors(FRONT, K_FRONT, pts, grad) == []
    _, pts_bare = _render(K_FRONT, [_wall(FRONT, _const(WALL_L))], ss=1)
    assert len(_doors(FRONT, K_FRONT, pts_bare, grad)) >= 1


# -- the raster -------------------------------------------------------------------------------


def test_raster_state_on_behind_and_in_front_of_the_plane():
    """Raster cells are classified by where the depth puts the surface at their pixel: on the
    plane (1), behind it (2: an opening onto a room whose back wall is 1 m further), in front
    (3: a panel 1.5 m nearer), unseen outside the image (0)."""

    def wall(s, h):  # an opening 1.2 m wide, 2.0 m high at s = -1.6 … -0.4
        return np.where((s > -1.6) & (s < -0.4) & (h < 2.0), np.nan, WALL_L)

    def panel(s, h):  # a panel at 2.5 m covering s = 0.4 … 1.6 (on the wall), h = 0.5 … 1.7
        on_wall = s * 4.0 / 2.5
        hw = (h + FLOOR_Z) * 4.0 / 2.5 - FLOOR_Z
        return np.where((on_wall > 0.4) & (on_wall < 1.6) & (hw > 0.5) & (hw < 1.7), 60.0, np.nan)

    walls = [_wall(FRONT, wall), ((-1.0, 0.0, 0.0), -5.0, _const(60.0)),
             ((-1.0, 0.0, 0.0), -2.5, panel)]
    lum, pts = _render(K_FRONT, walls, ss=1)
    r = wall_raster(FRONT, FLOOR_Z, 2.6, ROT, K_FRONT, pts, _grad(lum))
    assert r.state.shape == r.seen.shape == r.vedge.shape == (len(r.z), len(r.s))

    def state(s0, s1, h0, h1):
        cols = (r.s > s0) & (r.s < s1)
        rows = (r.z > h0) & (r.z < h1)
        return r.state[np.ix_(rows, cols)]

    assert (state(-1.5, -0.5, 0.1, 1.9) == 2).all()  # opening: behind the plane
    assert (state(0.5, 1.5, 0.6, 1.6) == 3).all()  # panel: in front
    assert (state(-0.3, 0.3, 0.1, 2.5) == 1).all()  # bare wall: on it
    assert (state(1.7, 2.5, 0.1, 2.5) == 1).all()
    # the wall at 4 m spans ±2.8 m of the 70° view: beyond it the cells are unseen
    outside = (np.abs(r.s) > 2.85)[None, :] & np.ones(len(r.z), bool)[:, None]
    assert not r.seen[outside].any() and (r.state[outside] == 0).all()


def test_raster_edge_strengths_follow_the_wall_axes_at_an_oblique_view():
    """On a wall seen at ~55° incidence, a vertical line on the wall is strong in the
    vertical-edge measure and a horizontal line (slanted by 15° in the image by perspective) in
    the horizontal-edge measure: both are taken across the wall's own axes as they appear in
    the image. (Where those axes are skewed by θ in the image, the other measure picks up
    |sin θ| of the gradient — up to ~0.6 near the floor here — so the margins are ratios.)"""

    def lines(s, h):  # a 4 cm vertical line at s = 2.2 m and a horizontal one at h = 1.0 m
        return np.where((np.abs(s - 2.2) < 0.02) | (np.abs(h - 1.0) < 0.02), FRAME_L, WALL_L)

    lum, pts = _render(K_WIDE, _scene_walls(SIDE, lines))
    r = wall_raster(SIDE, FLOOR_Z, 2.6, ROT, K_WIDE, pts, _grad(lum))
    js = np.argmin(np.abs(r.s - 2.22))  # the vertical line's edge at s = 2.22
    rows = ((r.z > 0.3) & (r.z < 0.9)) | ((r.z > 1.1) & (r.z < 2.2))
    v_at_v = r.vedge[rows, js - 1:js + 2].max(1)
    h_at_v = r.hedge[rows, js - 1:js + 2].max(1)
    assert (v_at_v > 5.0).all()
    assert (v_at_v > 1.4 * h_at_v).all()
    iz = np.argmin(np.abs(r.z - 1.02))  # the horizontal line's edge at h = 1.02
    cols = ((r.s > 1.6) & (r.s < 2.1)) | ((r.s > 2.3) & (r.s < 4.5))
    h_at_h = r.hedge[iz - 1:iz + 2, cols].max(0)
    v_at_h = r.vedge[iz - 1:iz + 2, cols].max(0)
    assert (h_at_h > 4.0).all()
    assert (h_at_h > 2.0 * v_at_h).all()


def test_builtin_segments_take_facade_options_and_name_unknown_fields():
    """``facade_options`` from a YAML config (lists) become a FacadeConfig; a misspelt field is
    an error that names the option and lists the known fields."""
    from sim2radar.reconstruct.segment_builtin import BuiltinSegments

    seg = BuiltinSegments(facade_options={"door_width_m": [0.8, 1.9], "lintel_cover": 0.5})
    assert seg.config.facade_config.door_width_m == (0.8, 1.9)
    assert seg.config.facade_config.lintel_cover == 0.5
    with pytest.raises(ValueError, match=r"facade_options.*'post_cov'.*post_cover"):
        BuiltinSegments(facade_options={"post_cov": 0.5})


def test_room_lower_than_the_nominal_door_top_is_searched_without_error():
    """Posts seen up to the image's top edge, below the lintel, ask for the nominal door top
    (``nominal_top_m``, 2.16 m); in a room whose ceiling is 2.0 m above the floor the wall
    raster ends below it. That is no doorway of door height, not an index error (found on a
    benchmark frame). The camera looks 1.5 m at the wall with its principal point near the
    image top, so the wall is seen from the floor up to 1.65 m only."""
    k = CameraIntrinsics(300.0, 300.0, 320.0, 50.0, 640, 480)
    plane = WallPlane(np.array([-1.0, 0.0, 0.0]), -1.5, (-2.0, 2.0))
    lum, pts = _render(k, [_wall(plane, _frame(-0.5, 0.5))])
    low_ceiling = FLOOR_Z + 2.0
    assert low_ceiling - FLOOR_Z < FacadeConfig().nominal_top_m
    assert find_facade_doors(plane, FLOOR_Z, low_ceiling, ROT, k, pts, _grad(lum)) == []


@pytest.mark.parametrize("border", [False, True])
def test_ceiling_below_the_lowest_lintel_gives_no_door_and_no_error(border):
    """A ceiling measured 1.94 m above the floor (below ``top_m[0]``, 1.95 m: e.g. a bulkhead
    taken for the ceiling) leaves no raster row where a lintel could be: a door frame, whole or
    cut by the image border, is then no doorway of door height, not an empty reduction (found
    on a 320×240 procedural frame)."""
    if border:
        lum, pts = _render(K_FRONT, [_wall(FRONT, _frame(2.3, 3.3))])
        plane, k, grad = FRONT, K_FRONT, _grad(lum)
    else:
        plane, k, _, pts, grad = _door_scene("front")
    low_ceiling = FLOOR_Z + 1.94
    assert low_ceiling - FLOOR_Z < FacadeConfig().top_m[0]
    assert find_facade_doors(plane, FLOOR_Z, low_ceiling, ROT, k, pts, grad) == []
    assert _doors(plane, k, pts, grad)  # the same frame under the scene's ceiling is a door
