"""Seeded generation of IFR-like indoor worlds: corridors, side rooms, doors, windows, props.

One seed -> one world, byte-identical on every run (Kubric's rule): every random decision draws
from a named sub-stream ``np.random.default_rng([seed, stream])``, never from a global RNG, so
adding a draw to one stream (say, props) leaves the layout of every seed unchanged.

Construction
------------
1. Layout: a main corridor along +x (``straight``), with a perpendicular branch somewhere along it
   (``t_junction``) or at its far end (``l_turn``). Spaces are axis-aligned free rectangles.
2. Side rooms are placed along the corridors' long walls, separated from the corridor by one wall
   thickness, each with a single or double door; free wall stretches may get "blind" closed doors,
   dead ends may get an end door.
3. Walls are the cells of a ``grid_m`` raster within one wall thickness of free space (Chebyshev
   inflation of the rectangles), owned by the lowest-index space that reaches them (so a
   corridor/room wall is one material), minus door and window openings, merged into boxes.
4. Windows go where the raster shows open outside behind a wall; then fire extinguishers,
   clutter (cabinets, radiators, bins), handrails and ceiling light panels.
Every object draws one material from ``WorldConfig.material_priors`` and an appearance from
:mod:`sim2radar.worlds.appearance`.

:func:`generate_world` runs this as eight named steps over one build state
(:class:`~sim2radar.worlds.generate_plan.Build`): the floor plan in
:mod:`sim2radar.worlds.generate_plan` (steps 1–3), its objects in
:mod:`sim2radar.worlds.generate_parts` (steps 4–8), then :func:`assemble` makes the meshes.
"""

from __future__ import annotations

import numpy as np

from sim2radar.mesh import MaterialMesh
from sim2radar.vocab import MATERIAL_CLASSES, SEMANTIC_CLASSES
from sim2radar.worlds.config import CLUTTER_KINDS, DOOR_STATES, LAYOUTS, WorldConfig
from sim2radar.worlds.frame import World, WorldObject
from sim2radar.worlds.generate_parts import (
    build_doors,
    build_walls_floors_ceilings,
    build_windows,
    place_lights,
    place_props,
)
from sim2radar.worlds.generate_plan import Build, plan_layout, plan_rooms_and_doors, plan_windows
from sim2radar.worlds.geometry import merge_arrays

__all__ = ["generate_world", "STAGE_VERSION"]

#: Bump when generation changes what a seed produces (part of every artifact key).
STAGE_VERSION = 3  # 2: doorway door boxes; material-correlated textures; 3: door hardware
#                    (sim2radar.door_parts): lever handles on both faces, hinge knuckles


def generate_world(seed: int, config: WorldConfig | None = None) -> World:
    """Generate the world of ``seed``.

    Parameters
    ----------
    seed : int >= 0
    config : WorldConfig, optional — defaults to ``WorldConfig()``.

    Returns
    -------
    World — meshes in the world frame (z up, floor at z = 0), one object per mesh.
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    cfg = config if config is not None else WorldConfig()
    if not isinstance(cfg, WorldConfig):
        raise TypeError(f"config must be a WorldConfig, got {type(cfg).__name__}")
    build = Build(int(seed), cfg)
    # the order is part of the seed -> world map: the steps share the materials and appearance
    # streams, so a step moved or added in between changes the looks of every later object
    plan_layout(build)                  # 1. corridors, path, corridor wall faces
    plan_rooms_and_doors(build)         # 2. side rooms, door plans, room wall faces
    plan_windows(build)                 # 3. wall raster, window plans
    build_doors(build)                  # 4. frames, leaves, handles, hinges; DoorSpecs
    build_windows(build)                # 5. sills, heads and panes
    build_walls_floors_ceilings(build)  # 6. walls (minus openings), floor and ceiling slabs
    place_props(build)                  # 7. extinguishers, clutter, handrails
    place_lights(build)                 # 8. ceiling light panels
    return assemble(build)


def assemble(build: Build) -> World:
    """The :class:`World` of a finished build: one :class:`MaterialMesh` (parts merged) and
    one :class:`WorldObject` per placed object, in the order they were added."""
    meshes, objects = [], []
    for i, o in enumerate(build.objs):
        assert o.semantic in SEMANTIC_CLASSES and o.material in MATERIAL_CLASSES
        v, f = merge_arrays(o.parts)
        meshes.append(MaterialMesh(v, f, material=o.material, name=o.name, semantic=o.semantic))
        objects.append(WorldObject(i, o.name, o.semantic, o.material, o.kind, o.door_index,
                                   o.space_index, o.appearance))
    return World(
        seed=build.seed, config=build.cfg, layout=build.layout,
        ceiling_height_m=float(build.height_m), spaces=tuple(build.spaces), meshes=tuple(meshes),
        objects=tuple(objects), doors=tuple(build.doors),
        path_world=np.asarray(build.path, dtype=np.float64),
    )


# re-exported names used by tests and statistics
DOOR_STATE_NAMES = DOOR_STATES
LAYOUT_NAMES = LAYOUTS
CLUTTER_NAMES = CLUTTER_KINDS
