"""Procedural indoor worlds (IFR-like corridors with rooms and doors) rendered by Mitsuba.

See :mod:`sim2radar.worlds.frame` for the data types and frame conventions.
"""

from sim2radar.worlds.config import (
    RigConfig,
    WorldConfig,
    WorldConfigError,
    load_worlds_config,
    make_rig_config,
    make_world_config,
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
)

__all__ = [
    "NO_INSTANCE",
    "Appearance",
    "DoorSpec",
    "RigConfig",
    "RigPose",
    "Space",
    "World",
    "WorldConfig",
    "WorldConfigError",
    "WorldFrame",
    "WorldObject",
    "load_worlds_config",
    "make_rig_config",
    "make_world_config",
]
