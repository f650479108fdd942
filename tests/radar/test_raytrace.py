"""Physical behaviour of the ray-traced radar (each test states a physical expectation)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.radar import RadarScene, simulate_frame
from tests.radar.conftest import dihedral, facing_plate


def _peak_db(frame) -> float:
    return float(10 * np.log10(4 * np.pi * (np.abs(frame.cube) ** 2).max()))


def _azimuth(points):
    return np.arctan2(points[:, 1], points[:, 0])


def test_plate_at_3m_is_detected_at_3m_and_boresight(mmwcas):
    frame = simulate_frame([facing_plate(3.0)], mmwcas)
    assert frame.n_points >= 1
    best = frame.points[0]  # strongest first
    rng = float(np.linalg.norm(best[:3]))
    assert rng == pytest.approx(3.0, abs=mmwcas.range_resolution_m)
    assert abs(math.atan2(best[1], best[0])) <= mmwcas.azimuth_resolution_rad
    # every detection lies on the plate's range (within one bin)
    assert np.all(np.abs(np.linalg.norm(frame.xyz, axis=1) - 3.0) < 2 * mmwcas.range_resolution_m)


def test_plate_return_matches_image_source_level(mmwcas):
    """A large flat metal plate in the near field reflects like a mirror: the coherent sum
    approaches the image-source field 1 / (2 r) (|Gamma| ~ 1), spread over a few cells."""
    frame = simulate_frame([facing_plate(3.0, size=2.0)], mmwcas, return_cube=True)
    total = np.abs(frame.cube.sum())  # all cells: the full PO integral
    assert total == pytest.approx(1 / (2 * 3.0), rel=0.15)


def test_two_plates_several_resolutions_apart_give_two_clusters(mmwcas):
    angle = 6 * mmwcas.azimuth_resolution_rad
    plates = [
        facing_plate(3 * math.cos(a), 3 * math.sin(a), size=0.3, name=f"p{i}")
        for i, a in enumerate((angle, -angle))
    ]
    frame = simulate_frame(plates, mmwcas)
    az = _azimuth(frame.points)
    left = np.abs(az - angle) <= mmwcas.azimuth_resolution_rad
    right = np.abs(az + angle) <= mmwcas.azimuth_resolution_rad
    assert left.any() and right.any()
    # the two strongest points are one per plate, and nothing strong lies between them
    top2 = np.sort(az[:2])
    assert top2[0] == pytest.approx(-angle, abs=mmwcas.azimuth_resolution_rad)
    assert top2[1] == pytest.approx(angle, abs=mmwcas.azimuth_resolution_rad)
    between = np.abs(az) < angle - 2 * mmwcas.azimuth_resolution_rad
    assert not np.any(frame.intensity_db[between] > frame.intensity_db[:2].min() - 10)


def test_plate_hidden_behind_another_is_not_seen(mmwcas):
    front = facing_plate(3.0, size=1.0, name="front")
    back = facing_plate(5.0, size=0.5, name="back")
    frame = simulate_frame([front, back], mmwcas)
    rng = np.linalg.norm(frame.xyz, axis=1)
    assert frame.n_points > 0
    assert not np.any(rng > 4.0)
    # without the front plate the back plate is seen at 5 m
    alone = simulate_frame([back], mmwcas)
    assert np.linalg.norm(alone.points[0, :3]) == pytest.approx(5.0, abs=mmwcas.range_resolution_m)


def test_dihedral_returns_strongly_only_with_two_bounces(mmwcas):
    scene = RadarScene(dihedral(3.5))
    one = scene.simulate(mmwcas.with_updates(max_bounces=1), return_cube=True)
    two = scene.simulate(mmwcas.with_updates(max_bounces=2), return_cube=True)
    assert two.stats["hits_per_bounce"][1] > 0
    assert _peak_db(two) > _peak_db(one) + 15.0
    # the double-bounce return sits at the crease range, on boresight
    best = two.points[0]
    assert np.linalg.norm(best[:3]) == pytest.approx(3.5, abs=mmwcas.range_resolution_m)
    assert abs(math.atan2(best[1], best[0])) <= mmwcas.azimuth_resolution_rad


def test_metal_returns_stronger_than_wood_at_the_same_place(mmwcas):
    metal = simulate_frame([facing_plate(3.0, material="metal")], mmwcas, return_cube=True)
    wood = simulate_frame([facing_plate(3.0, material="wood")], mmwcas, return_cube=True)
    # |Gamma| 0.999 vs 0.17 at normal incidence -> ~15 dB
    assert _peak_db(metal) > _peak_db(wood) + 10.0
    assert metal.points[0, 3] > wood.points[0, 3] + 10.0


def test_surface_at_grazing_incidence_returns_weakly(mmwcas):
    facing = simulate_frame([facing_plate(3.0)], mmwcas, return_cube=True)
    tilted = simulate_frame(
        [facing_plate(3.0, tilt_rad=math.radians(70))], mmwcas, return_cube=True
    )
    assert _peak_db(tilted) < _peak_db(facing) - 20.0


def test_return_power_falls_with_range(mmwcas):
    near = simulate_frame([facing_plate(2.0, size=0.3)], mmwcas)
    far = simulate_frame([facing_plate(6.0, size=0.3)], mmwcas)
    assert near.points[0, 3] > far.points[0, 3] + 6.0


def test_empty_field_of_view_gives_no_points(mmwcas):
    behind = facing_plate(-3.0)  # behind the radar
    frame = simulate_frame([behind], mmwcas)
    assert frame.n_points == 0 and frame.stats["n_hits"] == 0


def test_half_wave_slab_reflects_far_less_than_a_half_space(mmwcas):
    """A glass layer one internal half-wavelength thick is nearly transparent at normal
    incidence (slab model, ITU-R P.2040-3 §3: |R| 0.07 vs 0.43 for the half-space)."""
    from sim2radar.em import complex_permittivity

    eta = complex_permittivity("glass", mmwcas.center_frequency_hz)
    half_wave_m = mmwcas.wavelength_m / (2 * np.sqrt(eta.real))
    plate = [facing_plate(3.0, material="glass")]
    half_space = simulate_frame(plate, mmwcas, return_cube=True)
    slab = simulate_frame(
        plate,
        mmwcas.with_updates(scattering={"slab_thickness_m": {"glass": half_wave_m}}),
        return_cube=True,
    )
    assert _peak_db(slab) < _peak_db(half_space) - 10.0
