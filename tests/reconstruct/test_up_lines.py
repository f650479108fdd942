"""Gravity from the image's vertical lines: ``vertical_line_planes`` and ``estimate_up``.

A camera 1.4 m above the floor, pitched 8° down and rolled 3°, sees eight 6 cm wide vertical
posts (floor to ceiling, 2.6–6 m away) in front of a wall whose foot is a long near-horizontal
floor line. The posts' edges are projections of 3D vertical lines, so in the image they
converge to the vertical vanishing point ``K·up``; each edge's interpretation plane (camera
centre + line) contains ``up``.
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np
import pytest

from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct.backproject import estimate_up, level_from_camera, vertical_line_planes
from tests.reconstruct._models import rotation_deg

K = CameraIntrinsics.from_fov(640, 480, 70.0)
POSTS_XY = [(3.0, 1.2), (3.5, -0.8), (4.0, 0.3), (2.6, -1.4), (5.0, 2.0), (4.5, -2.2),
            (6.0, -0.2), (3.2, 2.1)]  # level frame: x forward, y left [m]
FLOOR_Z, CEIL_Z = -1.4, 1.3


# world up in the camera frame of a camera pitched 8° down, then rolled 3°
UP = rotation_deg(2, 3.0) @ np.array([0.0, -math.cos(math.radians(8)), -math.sin(math.radians(8))])
LEVEL = level_from_camera(UP)[:3, :3]  # camera → level; rows: forward, left, up


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(min(1.0, abs(float(a @ b)) / np.linalg.norm(a) / np.linalg.norm(b))))


def _project(p_level: np.ndarray) -> np.ndarray:
    pc = np.asarray(p_level, np.float64) @ LEVEL  # level → camera
    return np.stack([K.fx * pc[:, 0] / pc[:, 2] + K.cx, K.fy * pc[:, 1] / pc[:, 2] + K.cy], -1)


@functools.cache
def _image() -> np.ndarray:
    """RGB: light wall, grey floor below the wall's foot 6 m ahead, dark posts (anti-aliased,
    sub-pixel corners)."""
    img = np.full((K.height, K.width, 3), 190, np.uint8)
    sh = 4

    def fill(corners, colour):
        poly = np.round(_project(np.array(corners)) * 2**sh).astype(np.int32)
        cv2.fillPoly(img, [poly], colour, cv2.LINE_AA, sh)

    fill([[6, 30, FLOOR_Z], [6, -30, FLOOR_Z], [1, -30, FLOOR_Z], [1, 30, FLOOR_Z]], (120,) * 3)
    for x, y in POSTS_XY:
        fill([[x, y + 0.03, FLOOR_Z], [x, y - 0.03, FLOOR_Z], [x, y - 0.03, CEIL_Z],
              [x, y + 0.03, CEIL_Z]], (40,) * 3)
    return img


@functools.cache
def _line_planes() -> np.ndarray:
    return vertical_line_planes(_image(), K)


def _normals(floor_error_deg: float = 0.0, error_axis: int = 0, seed: int = 0) -> np.ndarray:
    """Camera-frame normals of a floor (4000, turned by ``floor_error_deg`` about camera axis
    ``error_axis``, as LiDAR-completed depth extrapolated below the beams gives) and of a front
    wall and two side walls (1500 + 2 × 750, correct: ⊥ up), with 0.01 rad noise."""
    rng = np.random.default_rng(seed)
    floor = np.tile(rotation_deg(error_axis, floor_error_deg) @ UP, (4000, 1))
    fwd, left = LEVEL[0], LEVEL[1]
    walls = np.concatenate([np.tile(-fwd, (1500, 1)), np.tile(-left, (750, 1)),
                            np.tile(left, (750, 1))])
    n = np.concatenate([floor, walls]) + rng.normal(0.0, 0.01, (7000, 3))
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_vertical_line_planes_contain_up():
    """Every returned interpretation-plane normal is a unit vector ⊥ the true up (within 1°):
    the posts' edges are found, all pass through the vertical vanishing point, and the long
    floor line (a horizontal 3D line) is left out."""
    m = _line_planes()
    assert m.ndim == 2 and m.shape[1] == 3
    np.testing.assert_allclose(np.linalg.norm(m, axis=1), 1.0, atol=1e-9)
    assert (np.abs(m @ UP) < math.sin(math.radians(1.0))).all()
    # at least one segment per post (repetition weights aside)
    assert len(np.unique(np.round(m, 6), axis=0)) >= len(POSTS_XY)


def test_lines_alone_fix_the_vanishing_direction():
    """The null direction of the stacked plane normals (smallest singular vector) is the
    vertical vanishing direction: within 0.2° of up."""
    m = _line_planes()
    v = np.linalg.svd(m, full_matrices=False)[2][-1]
    assert _angle_deg(v, UP) < 0.2


def test_no_lines_in_a_blank_image():
    """A uniform image has no line segments: an empty (0, 3) array, and ``estimate_up`` then
    keeps the normals' answer."""
    m = vertical_line_planes(np.full((K.height, K.width, 3), 128, np.uint8), K)
    assert m.shape == (0, 3)
    n = _normals()
    np.testing.assert_allclose(estimate_up(n, line_planes=m), estimate_up(n))


@pytest.mark.parametrize("error_deg, axis", [
    (15.0, 0),
    (8.0, 2),
    (15.0, 2),
], ids=["pitch-15", "roll-8", "roll-15"])
def test_lines_correct_up_from_extrapolated_floor_normals(error_deg, axis):
    """Floor normals turned by 8–15° (in pitch or roll; the correct wall normals too few to
    outvote them) put the normals-only up that far off; the image's vertical lines bring it
    within 2° of the truth."""
    n = _normals(error_deg, axis)
    err_normals = _angle_deg(estimate_up(n), UP)
    err_lines = _angle_deg(estimate_up(n, line_planes=_line_planes()), UP)
    assert err_normals > 0.4 * error_deg
    assert err_lines < 2.0
    assert err_normals > err_lines + 3.0


def test_lines_do_not_move_a_consistent_estimate():
    """With a correct floor and walls the normals already give up (< 0.5°), and the lines,
    which agree with it, change the answer by less than 0.5°."""
    n = _normals()
    up_normals = estimate_up(n)
    up_lines = estimate_up(n, line_planes=_line_planes())
    assert _angle_deg(up_normals, UP) < 0.5
    assert _angle_deg(up_lines, up_normals) < 0.5
    assert up_lines @ np.array([0.0, -1.0, 0.0]) > 0  # the side of −y (image up)
