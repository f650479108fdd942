"""Rendering: exact maps agree with the geometry, LiDAR on surfaces, determinism, door flags."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.camera import back_project, project
from sim2radar.vocab import MATERIAL_CLASSES, SEMANTIC_CLASSES
from sim2radar.worlds import NO_INSTANCE, render_frame, rig_extrinsics, rig_pose, trajectory
from tests.worlds._helpers import SMALL_RIG, point_triangle_distance


def _world_points(frame):
    pts = back_project(frame.depth_m, frame.intrinsics).reshape(-1, 3)
    c2w = frame.camera_to_world
    return pts @ c2w[:3, :3].T + c2w[:3, 3]


def test_frame_shapes_and_dtypes(frames3):
    f = frames3[0]
    h, w = SMALL_RIG.height, SMALL_RIG.width
    assert f.rgb.shape == (h, w, 3) and f.rgb.dtype == np.uint8
    assert f.depth_m.shape == (h, w) and f.depth_m.dtype == np.float32
    assert f.normals.shape == (h, w, 3) and f.normals.dtype == np.float32
    assert f.instance_id.dtype == np.int32
    assert f.semantic_id.dtype == np.uint8 and f.material_id.dtype == np.uint8
    assert f.lidar_points.dtype == np.float32 and f.lidar_points.shape[1] == 3
    assert f.door_boxes_world.shape == f.door_boxes_radar.shape == (len(f.door_visible), 7)
    assert f.semantic_id.max() < len(SEMANTIC_CLASSES)
    assert f.material_id.max() < len(MATERIAL_CLASSES)
    # corridors are closed: every primary ray hits something
    assert (f.instance_id != NO_INSTANCE).all() and (f.depth_m > 0).all()


def test_depth_lies_on_the_pixel_instance_surface(world3, frames3):
    """Back-projected depth lies on the mesh of the pixel's own instance within 1 cm — this
    checks depth against geometry and masks against depth, boundary pixels included."""
    for f in frames3:
        pts = _world_points(f)
        inst = f.instance_id.ravel()
        # include every boundary pixel (instance differs from a 4-neighbour) plus a sample
        ids = f.instance_id
        boundary = np.zeros_like(ids, bool)
        boundary[:, 1:] |= ids[:, 1:] != ids[:, :-1]
        boundary[:, :-1] |= ids[:, 1:] != ids[:, :-1]
        boundary[1:, :] |= ids[1:, :] != ids[:-1, :]
        boundary[:-1, :] |= ids[1:, :] != ids[:-1, :]
        sel = np.flatnonzero(boundary.ravel())
        sel = np.union1d(sel, np.arange(0, inst.size, 7))
        assert boundary.sum() > 20
        for i in np.unique(inst[sel]):
            pix = sel[inst[sel] == i]
            d = point_triangle_distance(pts[pix], world3.meshes[i].triangles)
            assert d.max() < 0.01, (world3.objects[i].name, d.max())


def test_semantic_and_material_maps_follow_instances(world3, frames3):
    f = frames3[1]
    for i in np.unique(f.instance_id):
        obj = world3.objects[i]
        m = f.instance_id == i
        assert (f.semantic_id[m] == SEMANTIC_CLASSES.index(obj.semantic)).all()
        assert (f.material_id[m] == MATERIAL_CLASSES.index(obj.material)).all()


def test_normals_are_unit_and_face_the_camera(frames3):
    f = frames3[0]
    n = f.normals.reshape(-1, 3)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-4)
    rays = back_project(np.ones_like(f.depth_m), f.intrinsics).reshape(-1, 3)
    assert (np.sum(n * rays, axis=1) < 0).all()
    # floor pixels (bottom rows) point up in the world
    c2w = f.camera_to_world
    floor = f.semantic_id.ravel() == SEMANTIC_CLASSES.index("floor")
    up = n[floor] @ c2w[:3, :3].T
    assert floor.any() and np.allclose(up[:, 2], 1.0, atol=1e-3)


def test_lidar_points_lie_on_surfaces(world3, frames3):
    f = frames3[0]
    assert len(f.lidar_points) > 500
    assert set(np.unique(f.lidar_ring)) == set(range(SMALL_RIG.lidar_beams))
    c2w = f.camera_to_world
    pts = f.lidar_points @ c2w[:3, :3].T + c2w[:3, 3]
    rng = np.random.default_rng(0)
    sample = pts[rng.choice(len(pts), 150, replace=False)]
    tris = np.concatenate([m.triangles for m in world3.meshes])
    assert point_triangle_distance(sample, tris).max() < 0.01
    # the LiDAR is mounted where the rig says, and lidar_to_camera is consistent
    ext = rig_extrinsics(SMALL_RIG)
    assert np.allclose(f.lidar_to_world, f.rig_to_world @ ext["lidar"])
    assert np.allclose(f.camera_to_world @ f.lidar_to_camera, f.lidar_to_world)
    # points in front of the camera project into the image
    uv, ok = project(f.lidar_points, f.intrinsics)
    assert ok.sum() > 20


def test_rendering_is_deterministic(world3):
    pose = trajectory(world3, 3, seed=0)[1]
    a = render_frame(world3, pose, SMALL_RIG)
    b = render_frame(world3, pose, SMALL_RIG)
    for name in ("rgb", "depth_m", "normals", "instance_id", "semantic_id", "material_id",
                 "lidar_points", "door_boxes_radar", "door_visible"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_rgb_is_aligned_with_the_maps(world3):
    """Ceiling light panels are the brightest things in the image, at the mask's pixels."""
    rig = SMALL_RIG.model_copy(update={"camera_pitch_deg": -25.0, "spp": 8})
    pose = trajectory(world3, 3, seed=0)[0]
    f = render_frame(world3, pose, rig)
    light_ids = [o.instance_id for o in world3.objects if o.kind == "light"]
    lights = np.isin(f.instance_id, light_ids)
    assert lights.sum() >= 4
    lum = f.rgb.astype(float).mean(axis=2)
    assert lum[lights].mean() > 200 > lum[~lights].mean() + 60


def test_door_boxes_and_flags(world3):
    door = next(d for d in world3.doors if d.leads_to >= 0)
    # stand 3 m in front of a room door, looking at it
    cx, cy, _ = door.center_world
    room = world3.spaces[door.leads_to].rect_m
    yaw_to_room = np.arctan2((room[2] + room[3]) / 2 - cy, (room[0] + room[1]) / 2 - cx)
    corridor = world3.spaces[0]
    if door.wall_axis == "x":
        y = corridor.rect_m[2] + 0.5 if cy > corridor.rect_m[3] - 0.1 else corridor.rect_m[3] - 0.5
        x, yaw = cx, np.arctan2(cy - y, 0.0)
    else:
        x, y = cx, cy
        yaw = yaw_to_room
    f = render_frame(world3, rig_pose(x, y, float(yaw)), SMALL_RIG, lidar=False)
    k = door.index
    assert f.door_visible[k] and f.door_in_fov[k] and f.door_in_range[k]
    assert f.door_visible_pixels[k] > 100
    # the door box in the radar frame is straight ahead, at the distance to the wall
    b = f.door_boxes_radar[k]
    assert b[0] > 0.5 and abs(np.degrees(np.arctan2(b[1], b[0]))) < 15
    # world -> radar -> world round trip
    r = f.radar_to_world
    back = r[:3, :3] @ b[:3] + r[:3, 3]
    assert np.allclose(back, f.door_boxes_world[k, :3], atol=1e-9)
    # doors behind the rig are neither in the FOV nor visible
    behind = f.door_boxes_radar[:, 0] < 0
    assert not (f.door_in_fov & behind).any() and not (f.door_visible & behind).any()


def test_bad_pose_is_refused(world3):
    with pytest.raises(ValueError, match="4, 4"):
        render_frame(world3, np.eye(3), SMALL_RIG)


def test_doors_per_frame_along_trajectories():
    """Trajectories walk past doors: most frames see a door and have one in the radar's view."""
    from sim2radar.worlds import RigConfig, generate_world

    rig = RigConfig(width=32, height=24, spp=1)
    visible, labelled = [], []
    for seed in range(12):
        world = generate_world(seed)
        for pose in trajectory(world, 2, seed=0):
            f = render_frame(world, pose, rig, rgb=False, lidar=False)
            visible.append(int(f.door_visible.sum()))
            labelled.append(int((f.door_in_fov & f.door_in_range).sum()))
            # a door seen by the camera from the rig is in the radar's (wider) azimuth FOV
            assert not (f.door_visible & ~f.door_in_fov & (f.door_boxes_radar[:, 0] > 2)).any()
    visible, labelled = np.array(visible), np.array(labelled)
    assert visible.mean() >= 1.0 and (visible > 0).mean() >= 0.75
    assert (labelled > 0).mean() >= 0.8
