"""The radar simulator runs on a generated world's ground-truth geometry and sees the door."""

from __future__ import annotations

import numpy as np

from sim2radar.radar import RadarScene, load_radar_config, simulate_frame
from sim2radar.worlds import render_frame, rig_pose, rig_velocity
from tests.worlds._helpers import SMALL_RIG


def test_radar_sees_a_door_of_a_generated_world(world3):
    door = next(d for d in world3.doors if d.leads_to >= 0 and d.wall_axis == "x")
    corridor = world3.spaces[0]
    cx, cy, _ = door.center_world
    # stand in the corridor 2.5 m before the door, on the far side, looking at it
    far_side = corridor.rect_m[2] + 0.4 if cy > corridor.rect_m[3] - 0.1 else corridor.rect_m[3] - 0.4
    x = cx - 2.5
    yaw = float(np.arctan2(cy - far_side, 2.5))
    frame = render_frame(world3, rig_pose(x, far_side, yaw), SMALL_RIG, lidar=False)
    k = door.index
    assert frame.door_in_fov[k] and frame.door_in_range[k]

    radar = load_radar_config(SMALL_RIG.radar_preset)
    # walking towards it (1 m/s): the device's range-Doppler map separates the door's returns
    # from the walls' by direction (at rest, one Doppler bin holds them all)
    result = simulate_frame(RadarScene(list(world3.meshes)), radar, frame.radar_to_world,
                            velocity_mps=rig_velocity(frame.radar_to_world, 1.0))
    pts = result.points[:, :3]
    assert len(pts) > 50
    b = frame.door_boxes_radar[k]
    c, s = np.cos(b[6]), np.sin(b[6])
    rel = pts - b[:3]
    local = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1], rel[:, 2]], 1)
    near_door = (np.abs(local) <= b[3:6] / 2 + 0.15).all(axis=1)
    assert near_door.sum() >= 5, near_door.sum()
    # the door is straight ahead-ish at the distance the ground truth says
    dist = np.linalg.norm(b[:2])
    assert abs(np.median(np.linalg.norm(pts[near_door, :2], axis=1)) - dist) < 0.6
