"""What a door returns through its hardware, against closed forms (sim2radar/door_parts.py).

Monostatic RCS of a perfectly conducting body in the optical regime (Knott, Shaeffer & Tuley,
*Radar Cross Section*, 2nd ed., Table 5.1): a cylinder of radius ``a`` and length ``L`` seen
broadside, ``sigma = 2 pi a L^2 / lambda``; a right dihedral of two ``a x b`` plates seen along
its symmetry plane, ``sigma = 8 pi a^2 b^2 / lambda^2``. The tracer's coherent sum over all
rays (``sigma = 4 pi R^4 |sum a e^{-jkL}|^2``, sim2radar/radar/returns.py) is compared with
them in the far field (range > 2 D^2 / lambda), with rays dense enough to sample each part
(0.006-0.01 deg: a few mm at the range used). 1 dB: the coherent sum over ~10-20 rays across
a curved part moves by up to ~0.7 dB with the ray grid's alignment (a 2 vs a 3 deg field of
view of the same spacing).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.door_parts import DoorHardware, hinge_parts, lever_handle_parts
from sim2radar.mesh import MaterialMesh, box_mesh, cylinder_mesh
from sim2radar.radar import RadarScene


def _rcs_dbsm(meshes, radar, range_m: float) -> float:
    paths = RadarScene(meshes).trace_paths(radar, prune_below_noise_db=None)
    k = 2 * math.pi / radar.wavelength_m
    total = np.sum(paths.amplitude * np.exp(-1j * k * paths.path_length_m))
    return 10 * math.log10(4 * math.pi * range_m**4 * abs(total) ** 2)


def _narrow(mmwcas, spacing_deg: float, bounces: int):
    return mmwcas.with_updates(azimuth_fov_deg=2.0, elevation_fov_deg=2.0,
                               ray_spacing_deg=spacing_deg, max_bounces=bounces)


def _metal(parts, name: str) -> list[MaterialMesh]:
    return [MaterialMesh(v, f, "metal", name=f"{name}{i}") for i, (v, f) in enumerate(parts)]


def test_cylinder_broadside_rcs_matches_the_closed_form(mmwcas):
    a, length, r = 0.02, 0.08, 6.0
    cyl = cylinder_mesh((r, 0.0, -length / 2), (0, 0, 1), a, length, 64, material="metal")
    want = 10 * math.log10(2 * math.pi * a * length**2 / mmwcas.wavelength_m)
    assert _rcs_dbsm([cyl], _narrow(mmwcas, 0.01, 1), r) == pytest.approx(want, abs=1.0)


@pytest.mark.parametrize("part", ["hinge", "lever"])
def test_door_hardware_returns_like_a_cylinder(mmwcas, part):
    """A hinge knuckle (7 mm x 100 mm) and a lever grip (9.5 mm x 130 mm) of the default
    DoorHardware, as generated (48 facets), broadside in their far field: within 1 dB of
    2 pi a L^2 / lambda."""
    hw = DoorHardware()
    if part == "hinge":
        a, length, r = hw.hinge_radius_m, hw.hinge_length_m, 8.0
        # one knuckle at mid-height of a leaf whose hinge line is 8 m ahead
        parts = [p for p in hinge_parts((r, 0.0), 2.0, hw)
                 if abs(p[0][:, 2].mean() - hw.hinge_heights_m[1]) < 1e-6]
        shift = np.array([0.0, 0.0, -hw.hinge_heights_m[1]])
    else:
        a, length, r = hw.lever_radius_m, hw.lever_length_m, 9.5
        # a leaf in the plane x = r + 0.06 facing the radar: the grip of its front handle runs
        # along y at x = r, 1.05 m up (the spindle, end-on, is left out)
        grips = lever_handle_parts((r + hw.lever_projection_m, length / 2 + hw.handle_inset_m),
                                   (0.0, 1.0), (-1.0, 0.0), 0.0, hw, sides=(1,))
        parts = [grips[1]]
        shift = np.array([0.0, 0.0, -hw.handle_height_m])
    meshes = [MaterialMesh(v + shift, f, "metal", name=part) for v, f in parts]
    want = 10 * math.log10(2 * math.pi * a * length**2 / mmwcas.wavelength_m)
    assert r > 2 * length**2 / mmwcas.wavelength_m  # far field
    assert _rcs_dbsm(meshes, _narrow(mmwcas, 0.006, 1), r) == pytest.approx(want, abs=1.0)


def test_dihedral_rcs_matches_the_closed_form(mmwcas):
    """A casing's step against the wall is a small dihedral: 6 x 6 cm metal plates at 90 deg,
    crease vertical 5 m ahead, seen along the symmetry plane: 8 pi a^2 b^2 / lambda^2 within
    1 dB (two bounces; one bounce alone is far weaker)."""
    a = b = 0.06
    r = 5.0
    half = b / 2 * math.sqrt(0.5)
    plates = [box_mesh([r - half, half, 0.0], [0.001, b, a], math.pi / 4, material="metal",
                       name="left"),
              box_mesh([r - half, -half, 0.0], [0.001, b, a], -math.pi / 4, material="metal",
                       name="right")]
    want = 10 * math.log10(8 * math.pi * a**2 * b**2 / mmwcas.wavelength_m**2)
    two = _rcs_dbsm(plates, _narrow(mmwcas, 0.01, 2), r)
    one = _rcs_dbsm(plates, _narrow(mmwcas, 0.01, 1), r)
    assert two == pytest.approx(want, abs=1.0)
    assert one < two - 10.0
