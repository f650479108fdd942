"""Physical behaviour of the ray-traced radar (each test states a physical expectation)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.mesh import box_mesh
from sim2radar.radar import RadarScene, simulate_frame
from tests.radar.conftest import dihedral, facing_plate


def _peak_db(frame) -> float:
    return float(10 * np.log10(4 * np.pi * (np.abs(frame.cube) ** 2).max()))


def _azimuth(points):
    return np.arctan2(points[:, 1], points[:, 0])


def _elevation(points):
    return np.arcsin(points[:, 2] / np.linalg.norm(points[:, :3], axis=1))


def pointed_plate(range_m, azimuth_deg, elevation_deg, side_m, name, material="metal"):
    """A thin square plate whose front face is ``range_m`` away in the direction
    (azimuth, elevation), facing the radar (tilted in both angles)."""
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    d = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    yaw = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    pitch = np.array([[math.cos(e), 0, -math.sin(e)], [0, 1, 0], [math.sin(e), 0, math.cos(e)]])
    m = np.eye(4)
    m[:3, :3] = yaw @ pitch
    m[:3, 3] = (range_m + 0.0025) * d
    return box_mesh([0, 0, 0], [0.005, side_m, side_m], 0.0, material=material,
                    name=name).transformed(m)


def _near(frame, range_m, tol_m=0.06):
    return np.abs(np.linalg.norm(frame.xyz, axis=1) - range_m) < tol_m


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
    """A large flat metal plate in the near field reflects like a mirror: the array sees the
    image source at 2 r, field 1 / (2 r) (|Gamma| ~ 1), in the boresight beam."""
    frame = simulate_frame([facing_plate(3.0, size=2.0)], mmwcas)
    best = frame.points[0]
    field = math.sqrt(10 ** (best[3] / 10) / (4 * math.pi))
    assert 20 * math.log10(field * 2 * 3.0) == pytest.approx(0.0, abs=1.0)


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


def test_a_ray_whose_surface_sends_nothing_on_is_not_traced_further(mmwcas):
    """A ray is continued only while its own carried power |C|^2 stays above 1e-10: a plate
    that scatters everything diffusely (S = 1, no specular field sent on) ends the rays that
    hit it first. In the symmetric dihedral half the rays hit that plate first, so bounce 1
    sees half the hits of the all-metal dihedral (a power summed over all rays instead of per
    ray would continue every ray: the same hits as all-metal)."""
    radar = mmwcas.with_updates(max_bounces=2,
                                scattering={"coefficients": {"metal": 0.0, "wood": 1.0}})
    metal = RadarScene(dihedral(3.5)).trace(radar, seed=1).hits_per_bounce
    wood_left = [dihedral(3.5, material="wood")[0], dihedral(3.5)[1]]
    mixed = RadarScene(wood_left).trace(radar, seed=1).hits_per_bounce
    assert mixed[0] == metal[0] > 0
    assert mixed[1] / metal[1] == pytest.approx(0.5, abs=0.1)


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


# --- regression tests of the binning simulator's former defects ------------------------------


def test_target_on_boresight_reads_its_full_return_on_a_beam_centre(mmwcas):
    """Defect (a): with an even number of azimuth bins boresight lay on a bin edge, so a
    point-like target there was split over two bins (~6 dB low) and placed 0.6 deg off.
    Now a beam is centred on boresight: a 5 cm plate at 3 m (beyond its far-field distance
    1.3 m) reads its PO RCS 4 pi A^2 / lambda^2 (within 1 dB; rays 0.1 deg apart sample its
    area to +0.4 dB) at 0 deg (+- 0.1 deg)."""
    radar = mmwcas.with_updates(elevation_fov_deg=10.0, ray_spacing_deg=0.1)
    side = 0.05
    frame = simulate_frame([facing_plate(3.0, size=side)], radar)
    best = frame.points[0]
    expected_db = 10 * math.log10(4 * math.pi * side**4 / radar.wavelength_m**2) - 40 * math.log10(3.0)
    assert best[3] == pytest.approx(expected_db, abs=1.0)
    assert math.degrees(math.atan2(best[1], best[0])) == pytest.approx(0.0, abs=0.1)
    assert mmwcas.n_azimuth_bins % 2 == 1
    assert mmwcas.azimuth_bins_rad[mmwcas.n_azimuth_bins // 2] == 0.0


def test_a_large_plate_gives_no_spurious_side_peaks(mmwcas):
    """Defect (a): cutting one plate's PO integral into angle bins left partial sums that did
    not cancel: a 1 m plate at 2 m gave side peaks at +-4.1 deg only 13 dB down. The array
    sums the whole plate: one point on boresight, nothing within 20 dB of it."""
    frame = simulate_frame([facing_plate(2.0, size=1.0)], mmwcas)
    best = frame.points[0]
    assert abs(math.degrees(math.atan2(best[1], best[0]))) < 0.2
    assert np.all(frame.intensity_db[1:] < best[3] - 20.0)


def test_two_scatterers_closer_than_the_resolution_give_one_point_between_them(mmwcas):
    """Defect (b): points sat at the power-weighted centroid of the true hit points in a cell,
    so two small plates 0.8 deg apart (resolution 1.18 deg) on either side of a bin edge came
    out at one plate's true azimuth. The array cannot tell them apart: one point, between."""
    plates = [pointed_plate(3.0, 0.4, 0.0, 0.04, "a"), pointed_plate(3.0, -0.4, 0.0, 0.04, "b")]
    frame = simulate_frame(plates, mmwcas)
    near = _near(frame, 3.0)
    assert near.sum() == 1
    assert math.degrees(_azimuth(frame.points[near])[0]) == pytest.approx(0.0, abs=0.15)


def test_two_plates_in_one_elevation_beam_give_one_point(mmwcas):
    """Defect (b): two plates at the same range and azimuth, +-8 deg in elevation (the
    elevation resolution is 14.6 deg), fell into two elevation cells and came out as two
    points at exactly +-8 deg. The array reads one elevation per azimuth peak."""
    plates = [pointed_plate(3.0, 0.0, 8.0, 0.05, "up"), pointed_plate(3.0, 0.0, -8.0, 0.05, "down")]
    frame = simulate_frame(plates, mmwcas)
    near = _near(frame, 3.0)
    assert near.sum() == 1
    assert abs(math.degrees(_elevation(frame.points[near])[0])) < 10.0


def test_angular_resolution_widens_as_one_over_cos_off_boresight(mmwcas):
    """Defect (b): angle bins were uniform in angle, so two in-phase scatterers 2.2 deg apart
    were resolved anywhere. The array's beams are uniform in sin(az): 2.2 deg is 1.65
    Rayleigh widths on boresight (two points) but 1.06 at 50 deg (one point)."""
    for centre, expected in ((50.0, 1), (0.0, 2)):
        plates = [pointed_plate(3.0, centre + 1.1, 0.0, 0.04, "a"),
                  pointed_plate(3.0, centre - 1.1, 0.0, 0.04, "b")]
        frame = simulate_frame(plates, mmwcas)
        near = _near(frame, 3.0)
        assert near.sum() == expected, centre
        az = np.degrees(_azimuth(frame.points[near]))
        if expected == 2:
            np.testing.assert_allclose(np.sort(az), [centre - 1.1, centre + 1.1], atol=0.3)
        else:
            assert az[0] == pytest.approx(centre, abs=0.5)


def test_one_pose_and_seed_give_the_same_bits_on_every_trace(mmwcas):
    """The sums are fixed point: the order of the threads' atomic adds does not change them
    (with float atomics, every trace of a cluttered scene differed in its last bits)."""
    meshes = [facing_plate(2.0 + 0.7 * k, y=0.9 * (k - 3), size=0.5, tilt_rad=0.3 * k,
                           name=f"p{k}", material=("metal", "wood", "concrete")[k % 3])
              for k in range(7)] + dihedral(4.0)
    scene = RadarScene(meshes)
    first = scene.trace(mmwcas, seed=5).accumulator
    assert np.abs(first.grid).max() > 0
    for _ in range(3):
        again = scene.trace(mmwcas, seed=5).accumulator
        assert again.grid.tobytes() == first.grid.tobytes()
        assert again.power.tobytes() == first.power.tobytes()
        assert again.range_w.tobytes() == first.range_w.tobytes()


def test_a_wall_touching_the_radar_stays_within_the_fixed_point_range(mmwcas):
    """A metal wall 5 cm in front of the radar (every ray hits it): its sums stay a million
    (amplitude) and a thousand (power) times under the 2^61-step limit."""
    from sim2radar.radar import raytrace

    wall = box_mesh([0.055, 0.0, 0.0], [0.01, 6.0, 6.0], 0.0, material="metal", name="wall")
    acc = RadarScene([wall]).trace(mmwcas, seed=1).accumulator
    assert 0 < np.abs(acc.grid).max() < raytrace.SUM_LIMIT * raytrace.AMPLITUDE_STEP / 1e6
    assert 0 < acc.power.max() < raytrace.SUM_LIMIT * raytrace.POWER_STEP / 1e3


def test_a_new_seed_per_frame_reuses_the_compiled_kernels(mmwcas):
    """The factory traces every frame with a new seed (new jitter, speckle and noise draws):
    after the first frame of a scene no kernel compiles again (buffers handed to Dr.Jit are
    64-byte aligned; unaligned ones made the same kernel recompile 0-3 times per frame)."""
    import drjit as dr

    from sim2radar.radar import RadarScene

    scene = RadarScene([facing_plate(3.0, size=1.0), facing_plate(4.0, 1.0, size=0.5,
                                                                  material="wood")])
    radar = mmwcas.with_updates(ray_spacing_deg=1.0)
    scene.simulate(radar, seed=0)
    scene.trace_paths(radar, seed=0)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        for seed in range(1, 6):
            scene.simulate(radar, seed=seed)
            scene.trace_paths(radar, seed=seed)
        compiled = [h for h in dr.kernel_history() if not h.get("cache_hit", True)]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert compiled == []


def test_element_patterns_weight_returns_off_boresight(mmwcas):
    """The same plate facing the radar at 3 m reads the two elements' two-way gain lower at
    45 deg azimuth than on boresight (hardware: a cos^q pattern of 100 deg beamwidth;
    link_budget.element_power_pattern): 2 x 10 log10(g), -4.7 dB (the kernel's twin in
    tests/radar/_reference.py applies the same gain, elevation included)."""
    from sim2radar.radar.link_budget import element_power_pattern

    def peak_db(x, y):
        frame = simulate_frame([facing_plate(x, y, size=0.5)], mmwcas)
        return float(frame.points[0, 3])

    r = 3.0
    on = peak_db(r, 0.0)
    az = math.radians(45.0)
    side = peak_db(r * math.cos(az), r * math.sin(az))
    want = 20 * math.log10(element_power_pattern(mmwcas, az, 0.0))
    assert side - on == pytest.approx(want, abs=0.7)


def test_the_bounce_loop_functions_trace_a_plate_through_the_scene_handle(mmwcas):
    """The bounce loop is functions over the scene handle (no base class): a metal plate 3 m
    ahead is hit by the boresight rays at bounce 0 with a round trip of 6 m and a visible
    return; the rays it mirrors straight back leave the scene (no second-bounce hit); a ray
    that ``intersect`` sends along the boresight hits the plate's front face at 3 m."""
    import drjit as dr

    from sim2radar.radar.raytrace_bounces import interactions, intersect, primary_rays
    from sim2radar.radar.raytrace_tables import material_tables, prepare_rays

    scene = RadarScene([facing_plate(3.0, size=0.4)])
    handle = scene.handle
    assert handle.n_triangles == scene.n_triangles == 12 and handle.materials == ("metal",)
    radar = mmwcas.with_updates(ray_spacing_deg=1.0)
    mi = handle.mi
    prep = prepare_rays(mi, handle.dr, radar, None, material_tables(mi, scene.materials, radar))
    hits = dr.zeros(mi.UInt32, radar.max_bounces)
    records = list(interactions(handle, radar, np.eye(4), prep, hits))
    assert [r.bounce for r in records] == list(range(radar.max_bounces))
    first = records[0]
    valid = np.asarray(first.valid.numpy(), bool)
    assert 0 < valid.sum() < prep.n_rays
    assert np.array_equal(valid, np.asarray(first.visible.numpy(), bool))  # facing the radar
    path = np.asarray(first.path_m.numpy())[valid]
    # the round trip is 6 m on boresight, 6 / cos(5.4 deg) to the plate's corner (0.28 m off)
    corner = math.atan(0.2 * math.sqrt(2.0) / 3.0)
    assert np.all((path > 6.0 - 1e-3) & (path < 6.0 / math.cos(corner) + 1e-3))
    hit_x = np.asarray(first.hit.x.numpy())[valid]
    np.testing.assert_allclose(hit_x, 3.0, atol=1e-4)
    assert list(hits.numpy()) == [int(valid.sum())] + [0] * (radar.max_bounces - 1)
    ray, origin = primary_rays(handle, prep, np.eye(4))
    assert dr.width(ray) == prep.n_rays
    boresight = mi.Ray3f(mi.Point3f(0.0, 0.0, 0.0), mi.Vector3f(1.0, 0.0, 0.0))
    si = intersect(handle, boresight, mi.Bool(True), None)
    assert bool(si.is_valid()[0]) and float(si.t[0]) == pytest.approx(3.0, abs=1e-5)
