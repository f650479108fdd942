"""simulate_frame / RadarScene: poses, seeds, outputs and input errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.mesh import MaterialMesh
from sim2radar.radar import (
    RadarFrame,
    RadarScene,
    array_geometry,
    load_radar_config,
    simulate_frame,
)
from sim2radar.radar.link_budget import noise_power_per_cell
from tests.radar.conftest import dihedral, facing_plate


def _pose(yaw_rad: float, t) -> np.ndarray:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    m = np.eye(4)
    m[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    m[:3, 3] = t
    return m


def test_frame_contents(mmwcas):
    frame = simulate_frame([facing_plate(3.0)], mmwcas, return_cube=True)
    assert isinstance(frame, RadarFrame)
    assert frame.points.dtype == np.float32 and frame.points.shape[1] == 4
    assert frame.cube.shape == (mmwcas.n_range_bins, mmwcas.n_azimuth_bins, mmwcas.n_elevation_bins)
    assert frame.cube.dtype == np.complex64
    assert len(frame.range_bins_m) == mmwcas.n_range_bins
    assert frame.stats["n_rays"] == mmwcas.n_rays and frame.stats["n_hits"] > 0
    assert {"trace", "detect", "total"} <= set(frame.stats["seconds"])
    assert np.all(np.diff(frame.intensity_db) <= 0)  # strongest first
    assert simulate_frame([facing_plate(3.0)], mmwcas).cube is None


def test_moving_radar_and_scene_together_gives_the_same_points(mmwcas):
    meshes = [facing_plate(3.0, 0.5, size=0.6, name="a"), *dihedral(4.5, size=0.6)]
    pose = _pose(math.radians(35.0), [2.0, -1.0, 0.5])
    moved = [m.transformed(pose) for m in meshes]
    radar = mmwcas.with_updates(max_bounces=2)
    a = simulate_frame(meshes, radar)
    b = simulate_frame(moved, radar, pose=pose)
    assert a.n_points > 0
    k = min(5, a.n_points)
    np.testing.assert_allclose(b.points[:k, :3], a.points[:k, :3], atol=0.01)
    np.testing.assert_allclose(b.points[:k, 3], a.points[:k, 3], atol=0.5)


def test_scene_is_built_once_and_reused_across_poses(mmwcas):
    scene = RadarScene([facing_plate(3.0)])
    first = scene.simulate(mmwcas, _pose(0.0, [0, 0, 0]))
    # radar stepped 1 m toward the plate: the plate appears at 2 m
    second = scene.simulate(mmwcas, _pose(0.0, [1.0, 0, 0]))
    assert np.linalg.norm(first.points[0, :3]) == pytest.approx(3.0, abs=0.04)
    assert np.linalg.norm(second.points[0, :3]) == pytest.approx(2.0, abs=0.04)
    # radar turned 90 deg left: the plate is now behind its right shoulder, out of view
    turned = scene.simulate(mmwcas, _pose(math.radians(90), [0, 0, 0]))
    assert turned.n_points == 0


def test_seed_is_reproducible_and_adds_noise(mmwcas):
    meshes = [facing_plate(3.0)]
    a = simulate_frame(meshes, mmwcas, seed=7, return_cube=True)
    b = simulate_frame(meshes, mmwcas, seed=7, return_cube=True)
    c = simulate_frame(meshes, mmwcas, seed=8, return_cube=True)
    np.testing.assert_array_equal(a.points, b.points)
    assert not np.array_equal(a.cube, c.cube)
    assert a.stats["noise_added"]
    # the plate is still found at 3 m
    assert np.linalg.norm(a.points[0, :3]) == pytest.approx(3.0, abs=mmwcas.range_resolution_m)


def test_receiver_noise_comes_from_the_link_budget(mmwcas):
    """Defect (c): the noise floor was a typed -110 dB. It is now the link budget's k T F f_s
    over echo scale and processing gain (about -118 dB for the cascade), and the beams of
    empty cells carry it times N / n (one channel per distinct position, binning.py)."""
    assert mmwcas.detection.noise_floor_db is None
    n0 = noise_power_per_cell(mmwcas)
    frame = simulate_frame([facing_plate(3.0)], mmwcas, seed=7, return_cube=True)
    assert frame.stats["noise_power_per_cell"] == pytest.approx(n0)
    empty = np.abs(frame.cube[200:].astype(np.complex128)) ** 2  # beyond the plate: noise only
    expected = n0 * array_geometry(mmwcas).noise_factor
    assert 10 * np.log10(empty.mean() / expected) == pytest.approx(0.0, abs=0.3)
    # a typed floor still overrides it
    loud = mmwcas.with_updates(detection={"noise_floor_db": -100.0})
    frame = simulate_frame([facing_plate(3.0)], loud, seed=7, return_cube=True)
    empty = np.abs(frame.cube[200:].astype(np.complex128)) ** 2
    expected = 1e-10 * array_geometry(loud).noise_factor
    assert 10 * np.log10(empty.mean() / expected) == pytest.approx(0.0, abs=0.3)


def test_no_seed_means_no_noise_and_add_noise_can_switch_it_off(mmwcas):
    plain = simulate_frame([facing_plate(3.0)], mmwcas, return_cube=True)
    assert not plain.stats["noise_added"]
    assert np.all(plain.cube[200:] == 0)  # deterministic, noise-free
    quiet = mmwcas.with_updates(detection={"add_noise": False})
    seeded = simulate_frame([facing_plate(3.0)], quiet, seed=3, return_cube=True)
    assert not seeded.stats["noise_added"] and np.all(seeded.cube[200:] == 0)


def test_noise_alone_gives_few_false_points(mmwcas):
    """A scene far beyond the maximum range: only receiver noise; CFAR (8 dB over the local
    mean, 10 dB over the noise) keeps false points rare."""
    frame = simulate_frame([facing_plate(50.0)], mmwcas, seed=11)
    assert frame.n_points <= 3


def test_preset_name_accepted(mmwcas):
    frame = simulate_frame([facing_plate(3.0)], "ti-mmwcas")
    assert frame.n_points > 0


def test_bad_inputs_are_explained(mmwcas):
    with pytest.raises(ValueError, match="no meshes"):
        simulate_frame([], mmwcas)
    bad = MaterialMesh(np.eye(3), [[0, 1, 2]], material="unobtainium", name="blob")
    with pytest.raises(ValueError, match="blob.*unobtainium.*concrete"):
        simulate_frame([bad], mmwcas)
    with pytest.raises(ValueError, match=r"\(4, 4\)"):
        simulate_frame([facing_plate(3.0)], mmwcas, pose=np.eye(3))
    with pytest.raises(ValueError, match="rotation"):
        simulate_frame([facing_plate(3.0)], mmwcas, pose=np.diag([2.0, 1, 1, 1]))


def test_signal_fidelity_runs_the_reference_chain_through_simulate_frame():
    """``fidelity: signal`` in the config sends a scene through traced paths, IF synthesis and
    the cascade chain: a 1 m metal plate facing the radar at 3 m is the strongest point, at
    3 m +- one range bin and on boresight, and every point carries a (zero, static) Doppler."""
    radar = load_radar_config("ti-mmwcas-reference")
    frame = simulate_frame([facing_plate(3.0)], radar, seed=1)
    assert frame.stats["fidelity"] == "signal" and frame.stats["n_paths"] > 0
    assert frame.points.shape[1] == 4 and frame.doppler_mps.shape == (frame.n_points,)
    assert np.all(frame.doppler_mps == 0.0) and frame.cube is None
    x, y, _, _ = frame.points[0]
    assert abs(np.hypot(x, y) - 3.0) <= radar.range_resolution_m + 1e-6
    assert abs(np.degrees(np.arctan2(y, x))) < 1.5
    assert {"trace", "signal", "total"} <= set(frame.stats["seconds"])
    ray = simulate_frame([facing_plate(3.0)], load_radar_config("ti-mmwcas"), seed=1)
    assert ray.stats["fidelity"] == "raytrace" and np.all(ray.doppler_mps == 0.0)


def test_moving_rig_gives_a_wall_facet_its_doppler():
    """The reference radar on a rig moving at v = 1.2 m/s along its heading past static wall
    facets at 0, 30 and -45 deg: the strongest point of each facet has Doppler -v cos(theta)
    within one Doppler bin (lambda / (2 N_chirps T_loop) = 0.048 m/s); standing still, zero."""
    radar = load_radar_config("ti-mmwcas-reference")
    facets = [(4.0, 0.0), (3.0, 30.0), (5.0, -45.0)]
    meshes = [facing_plate(r * math.cos(math.radians(a)), r * math.sin(math.radians(a)),
                           size=0.4, material="concrete", name=f"facet{i}")
              for i, (r, a) in enumerate(facets)]
    scene = RadarScene(meshes)
    v = 1.2
    t_loop = radar.n_tx * radar.chirp_period_s
    bin_mps = radar.wavelength_m / (2 * radar.n_chirps * t_loop)
    moving = simulate_frame(scene, radar, seed=3, velocity_mps=[v, 0.0, 0.0])
    still = simulate_frame(scene, radar, seed=3)
    assert np.all(still.doppler_mps == 0.0)
    r = np.linalg.norm(moving.xyz, axis=1)
    az = np.degrees(np.arctan2(moving.xyz[:, 1], moving.xyz[:, 0]))
    for rng, ang in facets:
        near = (np.abs(r - rng) < 0.15) & (np.abs(az - ang) < 3.0)
        assert near.any(), (rng, ang)
        best = np.flatnonzero(near)[np.argmax(moving.intensity_db[near])]
        assert moving.doppler_mps[best] == pytest.approx(-v * math.cos(math.radians(ang)),
                                                         abs=bin_mps)
