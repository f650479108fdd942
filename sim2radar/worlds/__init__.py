"""Procedural indoor worlds (IFR-like corridors with rooms and doors) rendered by Mitsuba.

    from sim2radar.worlds import generate_world, trajectory, render_frame, RigConfig
    world = generate_world(seed=7)                       # World: meshes, objects, doors
    poses = trajectory(world, n_frames=10, seed=0)       # list[RigPose]
    frame = render_frame(world, poses[0], RigConfig())   # WorldFrame: rgb, depth, masks, LiDAR

See :mod:`sim2radar.worlds.frame` for the data types and frame conventions.
"""

from sim2radar.worlds.config import (
    WALKING_SPEED_MPS,
    RigConfig,
    RigMotion,
    WorldConfig,
    WorldConfigError,
    load_worlds_config,
    make_rig_config,
    make_world_config,
    radar_view,
)
from sim2radar.worlds.frame import (
    NO_INSTANCE,
    Appearance,
    DoorSpec,
    RigPose,
    Space,
    World,
    WorldFrame,
    WorldObject,
    world_id_for,
)
from sim2radar.worlds.generate import STAGE_VERSION, generate_world
from sim2radar.worlds.render import RENDER_VERSION, cast_rays, render_frame, rig_extrinsics
from sim2radar.worlds.trajectory import rig_pose, rig_velocity, trajectory

__all__ = [
    "NO_INSTANCE",
    "RENDER_VERSION",
    "STAGE_VERSION",
    "WALKING_SPEED_MPS",
    "Appearance",
    "DoorSpec",
    "RigConfig",
    "RigMotion",
    "rig_velocity",
    "RigPose",
    "Space",
    "World",
    "WorldConfig",
    "WorldConfigError",
    "WorldFrame",
    "WorldObject",
    "cast_rays",
    "generate_world",
    "load_worlds_config",
    "make_rig_config",
    "make_world_config",
    "radar_view",
    "render_frame",
    "rig_extrinsics",
    "rig_pose",
    "trajectory",
    "world_id_for",
]
