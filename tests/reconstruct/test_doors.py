"""Door-box fitting from door-segment points."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.evaluate.reconstruction import box_iou_3d
from sim2radar.reconstruct.doors import (
    DoorFitConfig,
    box_corners,
    dedupe_boxes,
    fit_door_box,
    fit_door_boxes,
    transform_boxes,
)


def _door_face(center_xy, width, height, heading, floor_z=-1.3, n=3000, seed=0):
    """Points on a vertical door face (as a camera sees it), level frame."""
    rng = np.random.default_rng(seed)
    s = rng.uniform(-width / 2, width / 2, n)
    z = rng.uniform(floor_z, floor_z + height, n)
    a = np.array([math.cos(heading), math.sin(heading)])
    xy = np.asarray(center_xy) + s[:, None] * a
    return np.column_stack([xy, z])


@pytest.mark.parametrize("heading_deg", [0.0, 30.0, 85.0, -45.0])
def test_fit_recovers_size_position_and_heading(heading_deg):
    h = math.radians(heading_deg)
    pts = _door_face([4.0, 1.5], 0.9, 2.05, h)
    box = fit_door_box(pts, DoorFitConfig(thickness_m=0.15, face_to_center_m=0.05))
    assert box[3] == pytest.approx(0.9, abs=0.03)
    assert box[5] == pytest.approx(2.05, abs=0.05)
    assert box[4] == pytest.approx(0.15)
    dh = (box[6] - h + math.pi / 2) % math.pi - math.pi / 2  # boxes are symmetric under pi
    assert abs(dh) < math.radians(1)
    assert -math.pi / 2 < box[6] <= math.pi / 2
    # the centre lies 5 cm behind the face, away from the camera at the origin
    face_xy = np.array([4.0, 1.5])
    n = np.array([-math.sin(h), math.cos(h)])
    if face_xy @ n < 0:
        n = -n
    np.testing.assert_allclose(box[:2], face_xy + 0.05 * n, atol=0.03)
    assert box[2] == pytest.approx(-1.3 + 2.05 / 2, abs=0.05)


def test_stray_wall_column_and_off_plane_points_are_ignored():
    pts = _door_face([5.0, -1.0], 1.0, 2.0, 0.0)
    wall_col = np.column_stack([np.full(200, 5.9), np.full(200, -1.03), np.linspace(-1.3, 1.3, 200)])
    jamb = np.column_stack([np.full(100, 4.5), np.linspace(-1.0, -1.2, 100), np.linspace(-1.3, 0.7, 100)])
    box = fit_door_box(np.vstack([pts, wall_col, jamb]))
    assert box[3] == pytest.approx(1.0, abs=0.05)
    assert box[0] == pytest.approx(5.0, abs=0.03)


def test_floor_snap_extends_a_door_whose_bottom_is_hidden():
    pts = _door_face([3.0, 1.0], 0.9, 1.8, 0.0, floor_z=-1.1)  # bottom 20 cm hidden
    box = fit_door_box(pts, floor_z_m=-1.3)
    assert box[2] - box[5] / 2 == pytest.approx(-1.3, abs=0.02)


def test_double_door_leaves_merge_and_separate_doors_do_not():
    left = _door_face([4.0, 1.2], 0.75, 2.0, 0.0, seed=1)
    right = _door_face([4.8, 1.2], 0.75, 2.0, 0.0, seed=2)  # 5 cm gap between leaves
    far = _door_face([8.0, 1.2], 0.9, 2.0, 0.0, seed=3)
    boxes, groups = fit_door_boxes([left, right, far, np.zeros((3, 3))])
    assert len(boxes) == 2
    assert sorted(map(sorted, groups)) == [[0, 1], [2]]
    double = boxes[[0 in g for g in groups].index(True)]
    assert double[3] == pytest.approx(1.55, abs=0.05)
    assert double[0] == pytest.approx(4.4, abs=0.03)


def test_no_door_points_give_no_boxes():
    boxes, groups = fit_door_boxes([])
    assert boxes.shape == (0, 7) and groups == []
    with pytest.raises(ValueError):
        fit_door_box(np.zeros((2, 3)))


def test_transform_boxes_matches_transformed_corners():
    box = np.array([4.0, 1.0, -0.3, 0.9, 0.15, 2.0, 0.2], np.float32)
    yaw = 0.7
    m = np.eye(4)
    m[:3, :3] = [[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]]
    m[:3, 3] = [1.0, -2.0, 1.2]
    moved = transform_boxes(box[None], m)[0]
    corners = box_corners(box) @ m[:3, :3].T + m[:3, 3]
    expected = box_corners(moved)
    # same corner set (order may differ by a half turn)
    d = np.linalg.norm(corners[:, None] - expected[None], axis=-1).min(axis=1)
    assert d.max() < 1e-4
    assert box_iou_3d(moved[None], np.array([[*moved[:6], moved[6] + math.pi]]))[0, 0] == pytest.approx(1)


def test_box_is_centred_in_the_wall_around_a_recessed_door():
    # wall face at y = 1.0 (seen from the origin), leaf recessed 10 cm behind it
    door = _door_face([4.0, 1.1], 0.9, 2.0, 0.0)
    rng = np.random.default_rng(5)
    wall = np.column_stack([rng.uniform(1.0, 7.0, 4000), np.full(4000, 1.0),
                            rng.uniform(-1.3, 1.4, 4000)])
    wall = wall[np.abs(wall[:, 0] - 4.0) > 0.5]
    cfg = DoorFitConfig(thickness_m=0.2)
    box = fit_door_box(door, cfg, wall_points=wall)
    assert box[1] == pytest.approx(1.1, abs=0.01)  # wall face + half the thickness
    assert box[4] == pytest.approx(0.2)
    no_wall = fit_door_box(door, DoorFitConfig(thickness_m=0.2, face_to_center_m=0.0))
    assert no_wall[1] == pytest.approx(1.1, abs=0.01)  # the door face itself


def test_a_door_fragment_near_the_floor_is_completed_to_the_doorway_height():
    # only 0.5-1.6 m above the floor seen (LiDAR-completed depth lost the rest)
    frag = _door_face([3.0, 1.0], 0.9, 1.1, 0.0, floor_z=-0.8)
    cfg = DoorFitConfig(snap_to_floor_m=0.8, min_top_m=2.0)
    box = fit_door_box(frag, cfg, floor_z_m=-1.3)
    assert box[2] - box[5] / 2 == pytest.approx(-1.3, abs=0.02)  # bottom on the floor
    assert box[2] + box[5] / 2 == pytest.approx(0.7, abs=0.02)  # top 2.0 m above it
    # a region far above the floor, topped above any doorway (a sign, a vent) is left alone
    high = _door_face([3.0, 1.0], 0.9, 0.8, 0.0, floor_z=0.8)
    box = fit_door_box(high, cfg, floor_z_m=-1.3)
    assert box[5] == pytest.approx(0.8, abs=0.03)
    # only the upper part seen (top at doorway height): the box reaches down to the floor
    upper = _door_face([3.0, 1.0], 0.9, 0.9, 0.0, floor_z=-0.15)  # top 2.05 m above the floor
    box = fit_door_box(upper, cfg, floor_z_m=-1.3)
    assert box[2] - box[5] / 2 == pytest.approx(-1.3, abs=0.02)
    assert box[5] == pytest.approx(2.05, abs=0.03)
    # default config (min_top_m 0): heights as measured
    assert fit_door_box(frag, floor_z_m=-1.3)[5] == pytest.approx(1.1, abs=0.03)


def test_box_corners_single_and_batched():
    box = np.array([1.0, 2.0, 0.5, 0.9, 0.17, 2.1, 0.3])
    one, many = box_corners(box), box_corners(np.stack([box, box]))
    assert one.shape == (8, 3) and many.shape == (2, 8, 3)
    assert np.allclose(many[1], one)
    assert np.allclose(one.mean(axis=0), box[:3])


def test_dedupe_keeps_the_wider_of_overlapping_boxes_in_one_wall():
    door = [2.66, 0.95, 0.0, 0.94, 0.17, 2.0, 0.0]
    fragment = [3.23, 0.94, 0.0, 0.39, 0.17, 2.0, 0.05]  # overlaps the door along the wall
    neighbour = [3.9, 0.95, 0.0, 0.9, 0.17, 2.0, 0.0]  # next door along the wall
    opposite = [2.7, -0.95, 0.0, 0.9, 0.17, 2.0, 0.0]  # facing wall
    out = dedupe_boxes(np.array([fragment, door, neighbour, opposite]))
    assert out.shape == (3, 7)
    assert not np.any(np.isclose(out[:, 3], 0.39))
    assert np.allclose(out[0], door)  # input order kept
    assert dedupe_boxes(np.zeros((0, 7))).shape == (0, 7)


def test_door_thickness_is_one_constant_the_worlds_mean_doorway_depth():
    """The doorway box spans its wall plus the frame's 1 cm lip on each face: the worlds' wall
    thickness range + 2 cm, whose middle is the default depth of every reconstructed doorway
    box (door fitting, facade doors, wall openings)."""
    from sim2radar.boxes import DOOR_THICKNESS_M
    from sim2radar.reconstruct.facade import FacadeConfig
    from sim2radar.reconstruct.segment_builtin import BuiltinSegments
    from sim2radar.worlds import WorldConfig, generate_world

    lo, hi = (t + 0.02 for t in WorldConfig().wall_thickness_m)
    assert DOOR_THICKNESS_M == pytest.approx((lo + hi) / 2, abs=1e-9)
    depths = [door.box_world[4] for seed in range(3) for door in generate_world(seed).doors]
    assert depths and all(lo - 1e-6 <= dy <= hi + 1e-6 for dy in depths)
    assert DoorFitConfig().thickness_m == FacadeConfig().thickness_m == DOOR_THICKNESS_M
    assert BuiltinSegments().config.door_thickness_m == DOOR_THICKNESS_M
