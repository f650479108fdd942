"""The ray tracer's frame detection in torch (sim2radar/radar/detection_torch.py) against the
NumPy chain it twins (sim2radar/radar/detection.py), on the CPU; the CUDA run is marked gpu.

Tolerances: both chains hold the channel signal in complex64 and refine peaks in float64; only
the order of float32 roundings differs (torch's FFT and sums vs SciPy's FFT, NumPy's einsum and
chirp-z transform), ~1e-7 of the strongest channel signal. Through the parabolic peak
refinement that moves a point by < 1e-6 m and its intensity by < 1e-4 dB here (measured: 1.2e-7
m, 8e-6 dB on a 20k-triangle corridor), so the tests assert 1e-5 m and 1e-3 dB, and the same
points and Doppler bins exactly. Receiver noise comes from a torch stream, so the noisy frames
are compared by their statistics.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.radar import RadarScene, cfar
from sim2radar.radar import detection_torch as dt
from sim2radar.radar.binning import array_geometry
from sim2radar.radar.detection import cell_noise_power, detect_frame
from sim2radar.radar.frame import detection_device, simulate_scene_frame
from tests.radar.conftest import dihedral, facing_plate

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def scene():
    plates = [facing_plate(2.0 + 0.6 * k, y=0.8 * (k - 2), size=0.5, tilt_rad=0.2 * k,
                           name=f"p{k}", material=("metal", "wood", "concrete")[k % 3])
              for k in range(5)]
    return RadarScene(plates + dihedral(4.5))


def _same_points(a: np.ndarray, b: np.ndarray) -> None:
    assert a.shape == b.shape and len(a) > 0
    np.testing.assert_allclose(a[:, :3], b[:, :3], atol=1e-5, rtol=0)
    np.testing.assert_allclose(a[:, 3], b[:, 3], atol=1e-3, rtol=0)


@pytest.mark.parametrize("velocity", [None, [1.2, 0.3, 0.0]])
def test_torch_detection_gives_the_numpy_point_cloud_without_noise(scene, mmwcas, velocity):
    host = simulate_scene_frame(scene, mmwcas, seed=None, velocity_mps=velocity, device=None)
    dev = simulate_scene_frame(scene, mmwcas, seed=None, velocity_mps=velocity, device="cpu")
    assert host.stats["detection_device"] == "host" and dev.stats["detection_device"] == "cpu"
    _same_points(host.points, dev.points)
    np.testing.assert_array_equal(host.doppler_mps, dev.doppler_mps)
    if velocity is not None:  # the moving rig really separates Doppler bins
        assert len(np.unique(dev.doppler_mps)) > 1


def test_trace_on_device_holds_the_bits_of_trace(scene, mmwcas):
    """The device sums are the host sums (the same fixed-point kernel, shared by DLPack)."""
    host = scene.trace(mmwcas, seed=4)
    dev = scene.trace_on_device(mmwcas, seed=4)
    assert dev.hits_per_bounce == host.hits_per_bounce and dev.n_rays == host.n_rays
    back = dev.accumulator.to_host()
    assert back.grid.tobytes() == host.accumulator.grid.tobytes()
    assert back.power.tobytes() == host.accumulator.power.tobytes()
    assert back.range_w.tobytes() == host.accumulator.range_w.tobytes()


@pytest.mark.parametrize("kind", ["ca", "caso", "os"])
@pytest.mark.parametrize("edges", ["ti", "wrap"])
def test_torch_cfar_is_the_numpy_cfar(kind, edges):
    rng = np.random.default_rng(3)
    power = rng.exponential(1.0, (96, 64))
    power[40, 10] = power[41, 30] = 60.0  # targets
    for axis, (guard, train) in ((0, (8, 8)), (1, (0, 4))):
        want, _ = cfar.cfar_1d(power, axis=axis, kind=kind, guard=guard, train=train,
                               alpha=5.0, edges=edges, discard=(10, 20))
        got = dt.cfar_1d(torch.as_tensor(power), axis=axis, kind=kind, guard=guard,
                         train=train, alpha=5.0, edges=edges, discard=(10, 20))
        np.testing.assert_array_equal(got.numpy(), want)
        assert want.sum() >= 1


def test_torch_receiver_noise_has_the_numpy_noise_statistics(scene, mmwcas):
    """The two-step noise draw in torch (integrated_power, row_noise; the NumPy pair is tested
    against the full draw in test_detection.py): the channel-integrated power of C = 134
    channels of noise variance N N0 is the chi-square law with 2C degrees of freedom (no
    signal) or its non-central form (with), and the completed rows add up to it, with N N0 per
    channel."""
    from scipy import stats

    geom = array_geometry(mmwcas)
    var = geom.n_elements * cell_noise_power(mmwcas)
    c, n = int(geom.present.sum()), 4000
    gen = dt.noise_generator(1, 2, "cpu")
    rng = np.random.default_rng(0)
    for snr in (0.0, 1.0):
        s = rng.standard_normal(c) + 1j * rng.standard_normal(c)
        s *= math.sqrt(snr * c * var) / np.linalg.norm(s)
        s_pow = float(np.sum(np.abs(s) ** 2))
        power, (par, rest) = dt.integrated_power(torch.full((n,), s_pow, dtype=torch.float64),
                                                 c, var, gen)
        nc = 2 * s_pow / var
        law = stats.ncx2(2 * c, nc) if nc > 0 else stats.chi2(2 * c)
        assert stats.kstest(power.numpy() / (var / 2), law.cdf).pvalue > 1e-3
        noise = dt.row_noise(torch.as_tensor(np.tile(s, (n, 1))), par, rest, gen).numpy()
        np.testing.assert_allclose(np.sum(np.abs(s + noise) ** 2, axis=1), power.numpy(),
                                   rtol=1e-9)
        assert np.mean(np.abs(noise) ** 2) == pytest.approx(var, rel=0.02)
    # a strong target keeps its strongest point, with or without noise, on either path
    host = simulate_scene_frame(scene, mmwcas, seed=9, device=None)
    dev = simulate_scene_frame(scene, mmwcas, seed=9, device="cpu")
    assert dev.stats["noise_added"] and host.stats["noise_added"]
    np.testing.assert_allclose(dev.points[0, :3], host.points[0, :3], atol=0.05)
    assert abs(dev.n_points - host.n_points) <= max(3, 0.2 * host.n_points)


def test_noise_generator_is_one_stream_per_seed_and_stream():
    a = torch.randn(4, generator=dt.noise_generator(5, 0x4E01, "cpu"))
    b = torch.randn(4, generator=dt.noise_generator(5, 0x4E01, "cpu"))
    c = torch.randn(4, generator=dt.noise_generator(5, 0x4E02, "cpu"))
    assert torch.equal(a, b) and not torch.equal(a, c)


def test_detection_runs_on_the_host_unless_mitsuba_traces_on_cuda():
    assert detection_device("llvm_ad_rgb") is None
    dev = detection_device("cuda_ad_rgb")
    assert (dev is None) == (not torch.cuda.is_available())


def test_the_empty_field_of_view_gives_no_points_on_the_device(mmwcas):
    far = RadarScene([facing_plate(-3.0)])  # behind the radar
    frame = simulate_scene_frame(far, mmwcas, seed=2, device="cpu")
    assert frame.n_points == 0 and frame.points.shape == (0, 4)


@pytest.mark.gpu
def test_cuda_detection_gives_the_host_point_cloud(mmwcas):
    """On a GPU with Mitsuba's cuda_ad_rgb the sums stay on the device; without noise its
    points are the host chain's (tolerances of the module doc)."""
    s = RadarScene([facing_plate(3.0, size=1.0), *dihedral(4.5)])
    if not s.variant.startswith("cuda"):
        pytest.skip(f"Mitsuba traces on {s.variant}")
    dev = simulate_scene_frame(s, mmwcas, seed=None, velocity_mps=[1.0, 0.0, 0.0])
    assert dev.stats["detection_device"].startswith("cuda")
    acc = s.trace(mmwcas).accumulator
    want = detect_frame(acc, mmwcas, velocity_mps=[1.0, 0.0, 0.0])
    _same_points(want.points, dev.points)
    assert math.isfinite(float(dev.points[:, 3].max()))
