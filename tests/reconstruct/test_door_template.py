"""The door template a fitted box brings into the reconstructed scene
(sim2radar/reconstruct/door_template.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.door_parts import DoorHardware
from sim2radar.mesh import box_mesh
from sim2radar.radar import RadarScene, load_radar_config
from sim2radar.reconstruct.door_template import DoorTemplateConfig, door_template_meshes

FLOOR_Z = -1.35
#: a doorway 4 m ahead in a wall across the view (its width along y: heading pi/2), 1 m wide,
#: 2.1 m high, through a 0.15 m wall (box depth 0.17 m)
BOX = np.array([4.0, 0.3, FLOOR_Z + 1.05, 1.0, 0.17, 2.1, math.pi / 2])
NEAR_FACE_X = 4.0 - 0.17 / 2
LEAF_X = 4.04   # the leaf's face, recessed behind the wall's near face


def _leaf_points(n=400, seed=0):
    rng = np.random.default_rng(seed)
    y = rng.uniform(BOX[1] - 0.4, BOX[1] + 0.4, n)
    z = rng.uniform(FLOOR_Z + 0.1, FLOOR_Z + 2.0, n)
    return np.column_stack([np.full(n, LEAF_X), y, z])


def test_template_puts_casing_handle_and_hinges_where_a_door_has_them():
    meshes = door_template_meshes(BOX[None], _leaf_points(), FLOOR_Z)
    by = {m.name: m for m in meshes}
    assert set(by) == {"door_template_0_casing", "door_template_0_hardware"}
    assert all(m.semantic == "door" and m.material == "metal" for m in meshes)
    cfg, hw = DoorTemplateConfig(), DoorHardware()
    casing = by["door_template_0_casing"].vertices
    # on the wall's near face, standing proud of it toward the camera, around the outline
    assert casing[:, 0].max() == pytest.approx(NEAR_FACE_X, abs=1e-5)
    assert casing[:, 0].min() == pytest.approx(NEAR_FACE_X - cfg.casing_depth_m, abs=1e-5)
    assert casing[:, 1].min() == pytest.approx(BOX[1] - 0.5, abs=1e-5)
    assert casing[:, 1].max() == pytest.approx(BOX[1] + 0.5, abs=1e-5)
    assert casing[:, 2].min() == pytest.approx(FLOOR_Z, abs=1e-5)
    assert casing[:, 2].max() == pytest.approx(BOX[2] + BOX[5] / 2, abs=1e-5)
    hardware = by["door_template_0_hardware"].vertices
    # the handle stands out of the leaf face toward the camera at handle height
    handle = hardware[np.abs(hardware[:, 2] - (FLOOR_Z + hw.handle_height_m)) < 0.02]
    assert handle[:, 0].min() == pytest.approx(LEAF_X - hw.lever_projection_m - hw.lever_radius_m,
                                               abs=2e-3)
    assert handle[:, 0].max() <= LEAF_X + 1e-5
    # hinges: knuckles at the three heights on the other jamb, on the leaf face
    lo, hi = FLOOR_Z + hw.hinge_heights_m[0], FLOOR_Z + BOX[5] + hw.hinge_heights_m[2]
    knuckles = hardware[np.abs(hardware[:, 2] - lo) < hw.hinge_length_m / 2 + 1e-6]
    assert knuckles[:, 0].mean() == pytest.approx(LEAF_X, abs=1e-3)
    assert np.sign(knuckles[:, 1].mean() - BOX[1]) != np.sign(handle[:, 1].mean() - BOX[1])
    assert np.any(np.abs(hardware[:, 2] - hi) < hw.hinge_length_m / 2 + 1e-5)


def test_template_without_door_points_uses_the_walls_face_and_can_be_off():
    meshes = door_template_meshes(BOX[None], None, None)
    hardware = next(m for m in meshes if m.name.endswith("hardware")).vertices
    # on the box's near face (knuckles centred on it)
    assert hardware[:, 0].max() <= NEAR_FACE_X + DoorHardware().hinge_radius_m + 1e-5
    assert door_template_meshes(BOX[None], None, None, DoorTemplateConfig(enabled=False)) == []
    assert door_template_meshes(np.zeros((0, 7)), None, None) == []


def test_the_radar_sees_a_templated_door_better_than_its_pixels_alone():
    """A wooden leaf recessed in a plasterboard wall, 4 m ahead, the rig walking toward it: the
    template's casing, handle and hinges add points inside the doorway box."""
    wall = [box_mesh([NEAR_FACE_X + 0.075, BOX[1] + side * 1.75, 0.0], [0.15, 2.5, 2.8],
                     material="plasterboard", name=f"wall{side}") for side in (-1, 1)]
    leaf = box_mesh([LEAF_X + 0.02, BOX[1], FLOOR_Z + 1.0], [0.04, 0.88, 2.0],
                    material="wood", name="leaf")
    radar = load_radar_config("ti-mmwcas")
    velocity = np.array([1.0, 0.0, 0.0])

    def inside(meshes) -> int:
        pts = RadarScene(meshes).simulate(radar, seed=3, velocity_mps=velocity).points
        d = pts[:, :3] - BOX[:3]
        return int(np.sum((np.abs(d[:, 0]) < 0.25) & (np.abs(d[:, 1]) < 0.65)
                          & (np.abs(d[:, 2]) < 1.2)))

    bare = inside([*wall, leaf])
    templated = inside([*wall, leaf, *door_template_meshes(BOX[None], _leaf_points(), FLOOR_Z)])
    assert templated > bare
