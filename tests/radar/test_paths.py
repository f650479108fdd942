"""Propagation paths of the reference radar (RadarScene.trace_paths) and the visibility query.

Every test states a physical expectation. Twin tolerance: the Dr.Jit tracer runs in float32
with tabulated Fresnel/slab/lobe coefficients (1025 / 257 samples, linear interpolation), the
NumPy twin (tests/radar/_reference.py) in float64 with exact coefficients; single-bounce
amplitudes agree to ~1e-6 of the strongest path, multi-bounce ones to ~0.3 % (float32 hit
points feed the next bounce), so the tests assert 1e-4 and 1 %.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from sim2radar.em import unpolarized_transmission
from sim2radar.mesh import box_mesh
from sim2radar.radar import PATH_KINDS, PathSet, RadarScene
from sim2radar.radar.fmcw import element_positions_m
from sim2radar.radar.link_budget import noise_power_per_cell
from sim2radar.radar.returns import directive_lobe, directive_normalisation
from tests.radar._reference import reference_paths
from tests.radar.conftest import dihedral, facing_plate

PLASTERBOARD_M = 0.0125  # a common gypsum board thickness [m]


@pytest.fixture(scope="module")
def small_radar(mmwcas):
    # narrow FOV and coarse rays keep the O(rays x triangles) twin fast
    return mmwcas.with_updates(azimuth_fov_deg=40.0, elevation_fov_deg=30.0, ray_spacing_deg=0.5)


@pytest.fixture(scope="module")
def slab_radar(mmwcas):
    """The reference radar's model: 3 bounces, directive lobes, transmission through slabs."""
    return mmwcas.with_updates(
        max_bounces=3,
        azimuth_fov_deg=60.0,
        elevation_fov_deg=40.0,
        scattering={
            "model": "directive",
            "transmission": True,
            "slab_thickness_m": {"plasterboard": PLASTERBOARD_M},
        },
    )


def _coherent(paths: PathSet, wavelength_m: float, mask=None) -> complex:
    """The field at the array's phase centre: sum of a e^{-jkL} (carrier phase put back)."""
    a = paths.amplitude * np.exp(-2j * np.pi / wavelength_m * paths.path_length_m)
    return complex(a.sum() if mask is None else a[mask].sum())


def _matched(got: PathSet, ref: dict) -> tuple[np.ndarray, np.ndarray]:
    """Indices pairing each traced path with the twin's (same first/last point and order)."""
    key_ref = np.c_[ref["departure_point_m"], ref["arrival_point_m"], ref["n_interactions"]]
    key_got = np.c_[got.departure_point_m, got.arrival_point_m, got.n_interactions]
    dist, idx = cKDTree(key_ref).query(key_got)
    ok = dist < 1e-3
    return np.nonzero(ok)[0], idx[ok]


# --- the NumPy twin -------------------------------------------------------------------------


@pytest.mark.parametrize("model", ["lambertian", "directive"])
def test_flat_plate_paths_match_the_numpy_twin(small_radar, model):
    radar = small_radar.with_updates(max_bounces=1, scattering={"model": model})
    plate = [facing_plate(3.0, 0.3, size=1.0, material="concrete", tilt_rad=0.05)]
    got = RadarScene(plate).trace_paths(radar, prune_below_noise_db=None)
    ref = reference_paths(plate, radar)
    assert len(got) == len(ref["amplitude"]) > 1000  # one path per ray on the plate
    i, j = _matched(got, ref)
    assert len(i) == len(got)
    scale = np.abs(ref["amplitude"]).max()
    assert np.abs(got.amplitude[i] - ref["amplitude"][j]).max() <= 1e-4 * scale
    np.testing.assert_allclose(got.path_length_m[i], ref["path_length_m"][j], atol=1e-4)
    assert np.array_equal(got.kind[i], ref["kind"][j])
    # a diffuse sample on every ray; the PO sample only near the specular point (where the
    # phase step between rays stays under pi: the Nyquist window), so both kinds occur
    assert {PATH_KINDS["mixed"], PATH_KINDS["diffuse"]} == set(np.unique(got.kind))


def test_multibounce_and_slab_paths_match_the_numpy_twin(small_radar):
    radar = small_radar.with_updates(
        max_bounces=3,
        scattering={"model": "directive", "transmission": True,
                    "slab_thickness_m": {"plasterboard": PLASTERBOARD_M}},
    )
    wall = box_mesh([2.0, 0, 0], [PLASTERBOARD_M, 3, 3], 0.0, material="plasterboard",
                    name="wall")
    for meshes in ([wall, facing_plate(4.0, size=0.5, name="target")], dihedral(4.0)):
        got = RadarScene(meshes).trace_paths(radar, seed=3, prune_below_noise_db=None)
        ref = reference_paths(meshes, radar, seed=3)
        assert len(got) == len(ref["amplitude"])
        for n in np.unique(ref["n_interactions"]):
            sel = ref["n_interactions"] == n
            a_ref = ref["amplitude"][sel] * np.exp(-2j * np.pi / radar.wavelength_m
                                                   * ref["path_length_m"][sel])
            a_got = _coherent(got, radar.wavelength_m, got.n_interactions == n)
            assert abs(a_got) == pytest.approx(abs(a_ref.sum()), rel=0.01), n


# --- physical expectations ------------------------------------------------------------------


def test_small_plate_in_its_far_field_has_the_po_rcs(mmwcas):
    """A 10 cm metal plate at 6 m (beyond its far-field distance 2 D^2 / lambda = 5.3 m)
    returns its physical-optics RCS 4 pi A^2 / lambda^2 (Knott §5.2) within 1 dB."""
    radar = mmwcas.with_updates(azimuth_fov_deg=10.0, elevation_fov_deg=10.0,
                                ray_spacing_deg=0.02)
    side, r = 0.1, 6.0
    paths = RadarScene([facing_plate(r, size=side)]).trace_paths(radar)
    sigma = 4 * np.pi * r**4 * abs(_coherent(paths, radar.wavelength_m)) ** 2
    expected = 4 * np.pi * side**4 / radar.wavelength_m**2
    assert 10 * np.log10(sigma / expected) == pytest.approx(0.0, abs=1.0)


def test_one_square_metre_plate_at_3m_returns_the_mirror_image_field(mmwcas):
    """The 1 m^2 plate at 3 m is deep in its near field (far field beyond 2 D^2 / lambda =
    527 m): the coherent sum of its paths is the PO integral of a mirror, the image source at
    2 r, |a| = 1 / (2 r) (within 1 dB), not the far-field 4 pi A^2 / lambda^2 (45 dB more)."""
    paths = RadarScene([facing_plate(3.0, size=1.0)]).trace_paths(mmwcas)
    a = abs(_coherent(paths, mmwcas.wavelength_m))
    assert 20 * np.log10(a * 2 * 3.0) == pytest.approx(0.0, abs=1.0)
    far_field = math.sqrt(4 * np.pi / mmwcas.wavelength_m**2 / (4 * np.pi)) / 3.0**2
    assert 20 * np.log10(far_field / a) > 40.0


def test_dihedral_gives_strong_two_interaction_paths_at_the_crease(mmwcas):
    paths = RadarScene(dihedral(3.5)).trace_paths(mmwcas.with_updates(max_bounces=2))
    two = paths.n_interactions == 2
    assert two.sum() > 100
    a2 = abs(_coherent(paths, mmwcas.wavelength_m, two))
    a1 = abs(_coherent(paths, mmwcas.wavelength_m, ~two))
    assert 20 * np.log10(a2 / a1) > 15.0  # the retro-reflection dominates
    # a 90 deg corner's double bounce has the length of the crease's round trip
    strong = two & (np.abs(paths.amplitude) > 0.5 * np.abs(paths.amplitude[two]).max())
    np.testing.assert_allclose(paths.range_m[strong], 3.5, atol=mmwcas.range_resolution_m)


def test_target_behind_a_plasterboard_wall_is_seen_through_it(slab_radar):
    """Through a 12.5 mm plasterboard wall (slab, ITU-R P.2040-3 eq. (43b)) the plate behind
    returns its unobstructed coherent field times T^2 (two passes): power ratio |T|^4 within
    1.5 dB (mean over seeds), carried by 3-interaction paths (through, plate, back)."""
    wall = box_mesh([2.0, 0, 0], [PLASTERBOARD_M, 3, 3], 0.0, material="plasterboard",
                    name="wall")
    target = facing_plate(4.0, size=0.5, name="target")
    walled, alone = RadarScene([wall, target]), RadarScene([target])
    ratios = []
    for seed in range(4):
        p_wall = walled.trace_paths(slab_radar, seed=seed)
        p_alone = alone.trace_paths(slab_radar, seed=seed)
        behind = p_wall.range_m > 3.0
        assert behind.sum() > 500
        assert np.all(p_wall.n_interactions[behind] >= 3)
        a_wall = abs(_coherent(p_wall, slab_radar.wavelength_m, behind))
        ratios.append(a_wall**2 / abs(_coherent(p_alone, slab_radar.wavelength_m)) ** 2)
    t = unpolarized_transmission("plasterboard", slab_radar.center_frequency_hz, 0.0,
                                 PLASTERBOARD_M)
    assert 10 * np.log10(np.mean(ratios) / abs(t) ** 4) == pytest.approx(0.0, abs=1.5)


def test_nothing_is_seen_behind_a_metal_wall_or_without_transmission(slab_radar):
    target = facing_plate(4.0, size=0.5, name="target")
    metal = box_mesh([2.0, 0, 0], [0.002, 3, 3], 0.0, material="metal", name="wall")
    paths = RadarScene([metal, target]).trace_paths(slab_radar, seed=0)
    assert len(paths) > 1000 and not np.any(paths.range_m > 3.0)
    plaster = box_mesh([2.0, 0, 0], [PLASTERBOARD_M, 3, 3], 0.0, material="plasterboard",
                       name="wall")
    opaque = slab_radar.with_updates(scattering={"transmission": False})
    paths = RadarScene([plaster, target]).trace_paths(opaque, seed=0)
    assert not np.any(paths.range_m > 3.0)


def test_range_rate_of_a_moving_radar_is_minus_v_dot_the_line_of_sight(mmwcas):
    """Static scene, radar moving at v (radar frame): single-interaction paths have
    range rate -v . u (u toward the scatterer); the plate ahead approaches at 1 m/s."""
    v = np.array([1.0, 0.3, -0.1])
    yaw = math.radians(30.0)
    pose = np.eye(4)
    pose[:3, :3] = [[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0],
                    [0, 0, 1]]
    pose[:3, 3] = [1.0, 2.0, 0.5]
    meshes = [m.transformed(pose) for m in [facing_plate(3.0), *dihedral(5.0, size=0.6)]]
    paths = RadarScene(meshes).trace_paths(mmwcas.with_updates(max_bounces=2), pose,
                                           velocity_mps=v)
    one = paths.n_interactions == 1
    u = paths.departure_point_m[one] / np.linalg.norm(paths.departure_point_m[one], axis=1,
                                                      keepdims=True)
    np.testing.assert_allclose(paths.range_rate_mps[one], -u @ v, atol=1e-9)
    strongest = np.argmax(np.abs(paths.amplitude) * one)
    assert paths.range_rate_mps[strongest] == pytest.approx(-1.0, abs=0.01)
    # a double bounce: half the sum over its two legs
    two = paths.n_interactions == 2
    u_d = paths.departure_point_m[two] / np.linalg.norm(paths.departure_point_m[two], axis=1,
                                                        keepdims=True)
    u_a = paths.arrival_point_m[two] / np.linalg.norm(paths.arrival_point_m[two], axis=1,
                                                      keepdims=True)
    np.testing.assert_allclose(paths.range_rate_mps[two], -0.5 * (u_d + u_a) @ v, atol=1e-9)
    assert np.all(RadarScene(meshes).trace_paths(mmwcas, pose).range_rate_mps == 0.0)


# --- the directive lobe ---------------------------------------------------------------------


@pytest.mark.parametrize("alpha", [0, 1, 4, 10, 2.5])
def test_directive_lobe_scatters_exactly_the_scattered_power(alpha):
    """f_s = lobe / F_alpha integrates to 1 over the half-space (total scattered power
    S^2 |Gamma|^2 of the incident), for several incidence angles: an independent quadrature
    against the closed form of Degli-Esposti et al. (2007)."""
    x, w = np.polynomial.legendre.leggauss(400)
    theta_s = 0.25 * np.pi * (x + 1)
    phi = (np.arange(800) + 0.5) * 2 * np.pi / 800
    for theta_i in (0.0, 0.4, 1.0, 1.4):
        cos_psi = (np.sin(theta_i) * np.sin(theta_s)[:, None] * np.cos(phi)[None]
                   + np.cos(theta_i) * np.cos(theta_s)[:, None])
        integral = (directive_lobe(cos_psi, alpha) * (0.25 * np.pi * w * np.sin(theta_s))[:, None]
                    ).sum() * 2 * np.pi / 800
        f = directive_normalisation(np.cos(theta_i), alpha)
        assert integral / f == pytest.approx(1.0, rel=1e-6)


def test_directive_lobe_peaks_at_the_specular_direction():
    """For incidence 40 deg, the scattered intensity is largest toward the specular direction
    and falls monotonically away from it in the plane of incidence."""
    theta_i = math.radians(40.0)
    theta_s = np.radians(np.linspace(-89.0, 89.0, 357))  # signed, specular at +40 deg
    cos_psi = np.cos(theta_s - theta_i)
    for alpha in (2.0, 6.0, 20.0):
        lobe = directive_lobe(cos_psi, alpha)
        peak = np.degrees(theta_s[np.argmax(lobe)])
        assert peak == pytest.approx(40.0, abs=0.5)
        right = lobe[theta_s >= theta_i]
        left = lobe[theta_s <= theta_i]
        assert np.all(np.diff(right) <= 0) and np.all(np.diff(left) >= 0)


def test_directive_backscatter_is_strongest_when_the_radar_sits_in_the_specular_direction(mmwcas):
    """A fully rough (S = 1: diffuse only) concrete plate tilted away from the radar: its
    return is strongest facing the radar and falls with tilt t like cos^{2 alpha} t
    F(0) / F(t) (monostatic cos psi_R = cos 2t: the radar leaves the lobe), relative to a
    Lambertian plate's cos t (which carries the shared |Gamma(t)|^2 and rays-on-plate)."""
    alpha = 6.0
    radar = mmwcas.with_updates(
        azimuth_fov_deg=30.0, elevation_fov_deg=30.0, max_bounces=1,
        scattering={"model": "directive", "lobe_exponent": {"concrete": alpha},
                    "coefficients": {"concrete": 1.0}},
    )
    lamb = radar.with_updates(scattering={"model": "lambertian"})
    tilts = np.radians([0.0, 15.0, 30.0, 45.0])
    power = {"directive": [], "lambertian": []}
    for tilt in tilts:
        scene = RadarScene([facing_plate(3.0, size=0.3, material="concrete", tilt_rad=tilt)])
        for name, cfg in (("directive", radar), ("lambertian", lamb)):
            p = scene.trace_paths(cfg)
            assert np.all(p.kind == PATH_KINDS["diffuse"])
            power[name].append(np.sum(np.abs(p.amplitude) ** 2))  # incoherent sum
    d, lm = np.array(power["directive"]), np.array(power["lambertian"])
    assert np.all(np.diff(d) < 0)
    shared = lm / lm[0] / np.cos(tilts)
    predicted = (np.cos(tilts) ** (2 * alpha) * directive_normalisation(1.0, alpha)
                 / directive_normalisation(np.cos(tilts), alpha)) * shared
    # the plate spans +-2.9 deg of incidence around its centre: 10 % of lobe curvature
    np.testing.assert_allclose(d / d[0], predicted, rtol=0.1)
    assert d[-1] / d[0] < 0.5 * lm[-1] / lm[0]


# --- keeping the path count manageable --------------------------------------------------------


def test_pruning_drops_only_paths_below_the_threshold(mmwcas):
    """Paths weaker than the receiver noise per cell minus the margin are dropped and
    accounted for. (The default margin, 40 dB, prunes little in small scenes; a margin of
    -50 dB, i.e. 50 dB above the noise, exercises it: it drops the diffuse-only samples,
    ~-72 dB at 3 m, and keeps the plate's physical-optics samples, ~-50 dB.)"""
    scene = RadarScene([facing_plate(3.0), facing_plate(9.0, 1.0, size=0.3, material="wood",
                                                         tilt_rad=1.2, name="far")])
    radar = mmwcas.with_updates(max_bounces=2)
    everything = scene.trace_paths(radar, prune_below_noise_db=None)
    pruned = scene.trace_paths(radar, prune_below_noise_db=-50.0)
    default = scene.trace_paths(radar)
    n0 = noise_power_per_cell(radar)
    threshold = n0 * 10**5
    assert pruned.stats["noise_power_per_cell"] == pytest.approx(n0)
    assert len(pruned) + pruned.stats["n_pruned"] == len(everything)
    assert np.all(np.abs(pruned.amplitude) ** 2 >= threshold)
    lost = np.abs(everything.amplitude) ** 2 < threshold
    assert lost.sum() == pruned.stats["n_pruned"] > 1000
    assert pruned.stats["pruned_power"] == pytest.approx(
        np.sum(np.abs(everything.amplitude[lost]) ** 2), rel=1e-6)
    # the plate at 3 m keeps its coherent return (within 1 dB even at this aggressive margin,
    # which also drops the tapered physical-optics samples at the edge of the Nyquist window)
    a_all = abs(_coherent(everything, radar.wavelength_m))
    assert abs(_coherent(pruned, radar.wavelength_m)) == pytest.approx(a_all, rel=0.11)
    assert default.stats["pruned_power"] < n0  # 40 dB under the noise: nothing that matters


def test_merging_keeps_the_field_at_the_phase_centre_and_across_the_array(mmwcas):
    """Merging paths that share 1 cm voxels (PathSet.merged) keeps the coherent sum at the
    phase centre exactly, and the beamformed field of the whole virtual array within 0.5 dB
    wherever it is within 20 dB of its peak (the documented per-element phase error)."""
    radar = mmwcas.with_updates(max_bounces=2, ray_spacing_deg=0.1, azimuth_fov_deg=60.0,
                                elevation_fov_deg=30.0)
    meshes = [facing_plate(2.0, 0.4, size=0.6, material="concrete", tilt_rad=0.3),
              *dihedral(3.0, size=0.5)]
    paths = RadarScene(meshes).trace_paths(radar, seed=1)
    merged = paths.merged(0.01, radar.wavelength_m)
    assert len(merged) < 0.8 * len(paths)
    assert merged.stats["n_paths_before_merge"] == len(paths)
    a, b = _coherent(paths, radar.wavelength_m), _coherent(merged, radar.wavelength_m)
    assert abs(a - b) <= 1e-9 * abs(a)

    # per virtual channel (t, r): L = |P_dep - tx| + inner + |P_arr - rx| (paths.py)
    tx, rx = element_positions_m(radar)
    k = 2 * np.pi / radar.wavelength_m

    def channels(p: PathSet) -> np.ndarray:
        inner = p.inner_length_m
        d_t = np.linalg.norm(p.departure_point_m[:, None] - tx[None], axis=2)  # (P, T)
        d_r = np.linalg.norm(p.arrival_point_m[:, None] - rx[None], axis=2)  # (P, R)
        s = np.zeros((radar.n_tx, radar.n_rx), dtype=complex)
        for i in range(radar.n_tx):
            s[i] = (p.amplitude[:, None] * np.exp(-1j * k * (d_t[:, i:i + 1] + inner[:, None]
                                                              + d_r))).sum(axis=0)
        return s.ravel()

    pos = radar.virtual_array_half_wl
    u = np.linspace(-0.6, 0.6, 241)
    steer = np.exp(-1j * np.pi * pos[:, 0][None] * u[:, None])  # azimuth beams (el = 0)
    beam_a = np.abs(steer @ channels(paths)) ** 2
    beam_b = np.abs(steer @ channels(merged)) ** 2
    strong = beam_a > beam_a.max() * 0.01
    assert np.abs(10 * np.log10(beam_b[strong] / beam_a[strong])).max() < 0.5


def test_path_set_merge_rejects_a_bad_voxel():
    p = PathSet.point_targets(np.array([[3.0, 0, 0], [3.001, 0, 0]]))
    with pytest.raises(ValueError, match="voxel_m"):
        p.merged(0.0, 0.004)
    m = p.merged(0.01, 0.004)
    assert len(m) == 1 and m.kind[0] == PATH_KINDS["diffuse"]


# --- the visibility query -------------------------------------------------------------------


def test_first_hit_distance_is_the_distance_to_the_nearest_surface():
    """A plate whose front face is 3 m ahead (world frame, shifted and turned scene)."""
    yaw = math.radians(-20.0)
    pose = np.eye(4)
    pose[:3, :3] = [[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0],
                    [0, 0, 1]]
    pose[:3, 3] = [5.0, -1.0, 2.0]
    scene = RadarScene([facing_plate(3.0).transformed(pose),
                        facing_plate(6.0, name="behind").transformed(pose)])
    fwd = pose[:3, :3] @ [1.0, 0, 0]
    origins = np.stack([pose[:3, 3], pose[:3, 3], pose[:3, 3] + [0, 0, 0.2]])
    dirs = np.stack([fwd * 2.0, -fwd, fwd])  # unnormalised ok; backwards misses
    t = scene.first_hit_distance(origins, dirs)
    assert t.dtype == np.float64 and t.shape == (3,)
    assert t[0] == pytest.approx(3.0, abs=1e-4)
    assert np.isinf(t[1])
    assert t[2] == pytest.approx(3.0, abs=1e-4)
    assert scene.first_hit_distance(np.zeros((0, 3)), np.zeros((0, 3))).shape == (0,)
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        scene.first_hit_distance(np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="non-zero"):
        scene.first_hit_distance(np.zeros((1, 3)), np.zeros((1, 3)))
