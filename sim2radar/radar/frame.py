"""One radar frame of a traced scene: the tracer's returns -> radar point cloud (+ cube).

:func:`simulate_scene_frame` asks a :class:`TracedScene` (the ray tracer's
:class:`~sim2radar.radar.raytrace.RadarScene`) for one pose's returns and turns them into a
:class:`RadarFrame`: beamforming, receiver noise and detection at ``fidelity: raytrace``, the
signal chain at ``fidelity: signal``. :func:`sim2radar.radar.simulate_frame` builds the scene
from meshes first.

Where the ``raytrace`` frame's detection runs (:func:`detection_device`): where Mitsuba traces
on CUDA, on that GPU in torch (:mod:`sim2radar.radar.detection_torch`: the sums never leave the
device, only the point cloud comes back; issue #31); otherwise on the host in NumPy
(:func:`sim2radar.radar.detection.detect_frame`), which on the project's 2-core CPU measured
faster than torch there (BENCHMARKS.md, "The radar on the device").
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, Protocol

import numpy as np

from sim2radar.radar.binning import TraceResult, add_receiver_noise, array_geometry, beamform
from sim2radar.radar.config import RadarConfig
from sim2radar.radar.detection import cell_noise_power, detect_frame
from sim2radar.radar.paths import PathSet

__all__ = ["DeviceTrace", "RadarFrame", "TracedScene", "detection_device",
           "simulate_scene_frame"]

#: Second seed word of the receiver-noise random stream (distinct from the ray jitter's).
NOISE_STREAM = 0x4E01
#: ... and of the noise on a returned beam cube (a picture; detection draws its own).
CUBE_NOISE_STREAM = 0x4E02


@dataclasses.dataclass(frozen=True, eq=False)
class RadarFrame:
    """One simulated radar frame.

    Attributes
    ----------
    points : (N, 4) float32
        x, y, z [m] in the radar frame (x forward, y left, z up), intensity [dB]
        (``10 log10(4 pi |a|^2)`` = RCS [dBsm] - 40 log10(range [m])), strongest first.
    doppler_mps : (N,) float32
        Radial velocity of each point [m/s] (positive = receding): the signal-level radar
        measures it; the ray tracer gives the range rate of the point's range-Doppler cell
        (its direction's, :func:`sim2radar.radar.detection.doppler_bins`; 0 at rest).
    cube : (n_range, n_az, n_el) complex64 or None
        Beamformed range-azimuth-elevation returns of the virtual array (``return_cube=True``;
        :mod:`sim2radar.radar.binning`), receiver noise included when a seed was given.
        ``None`` at ``fidelity: signal`` (use :func:`sim2radar.radar.signal.simulate_signal_frame`
        with ``return_cubes=True`` for its IF samples and range-Doppler cube).
    range_bins_m : (n_range,) float32 — range bin centres [m].
    azimuth_bins_rad : (n_az,) float32 — azimuth beam centres [rad] (+ = left), uniform in
        ``sin`` (one on boresight).
    elevation_bins_rad : (n_el,) float32 — elevation beam centres [rad] (+ = up), uniform in
        ``sin``.
    stats : dict
        ``fidelity``, ``max_range_m`` (R_max [m]); at ``raytrace``: ``n_rays``, ``n_hits``
        (first bounce), ``hits_per_bounce``, ``n_points``, ``n_triangles``, ``variant``,
        ``seed``, ``noise_power_per_cell`` (N0 [sim. |a|^2]), ``noise_added``, ``detection_device``
        (``host`` or the torch device, :func:`detection_device`) and ``seconds``
        per stage (``rays``, ``trace``, ``readback``, ``beamform``, ``detect``, ``total``); at
        ``signal``: ``n_paths``, the signal chain's stats
        (:class:`~sim2radar.radar.signal.SignalFrame`) and ``seconds`` (``trace``,
        ``signal``, ``total``).
    """

    points: np.ndarray
    doppler_mps: np.ndarray
    cube: np.ndarray | None
    range_bins_m: np.ndarray
    azimuth_bins_rad: np.ndarray
    elevation_bins_rad: np.ndarray
    stats: dict[str, Any]

    @property
    def n_points(self) -> int:
        return int(len(self.points))

    @property
    def xyz(self) -> np.ndarray:
        """(N, 3) float32 — point positions [m]."""
        return self.points[:, :3]

    @property
    def intensity_db(self) -> np.ndarray:
        """(N,) float32 — point intensities [dB]."""
        return self.points[:, 3]


@dataclasses.dataclass(frozen=True)
class DeviceTrace:
    """:class:`~sim2radar.radar.binning.TraceResult` with the sums on the tracer's device
    (:meth:`sim2radar.radar.raytrace.RadarScene.trace_on_device`).

    Attributes
    ----------
    accumulator : DeviceAccumulator — torch tensors (:mod:`sim2radar.radar.detection_torch`).
    n_rays : int; hits_per_bounce : tuple of int; seconds : dict — as in ``TraceResult``.
    """

    accumulator: Any
    n_rays: int
    hits_per_bounce: tuple[int, ...]
    seconds: dict[str, float]


def detection_device(variant: str):
    """The torch device a ``raytrace`` frame of a scene traced on Mitsuba ``variant`` is
    detected on: the CUDA device (:func:`sim2radar.hardware.torch_device`) for a ``cuda_*``
    variant when torch sees it, else ``None`` (NumPy on the host: on the 2-core CPU the NumPy
    chain measured faster than torch's, and it keeps NumPy's noise stream)."""
    if not variant.startswith("cuda"):
        return None
    from sim2radar.hardware import torch_device

    device = torch_device()
    return device if device.type == "cuda" else None


class TracedScene(Protocol):
    """What :func:`simulate_scene_frame` needs of a scene: the ray tracer's two outputs and two
    counters for the frame's stats (:class:`~sim2radar.radar.raytrace.RadarScene` has them; to
    detect on a torch device it also needs ``trace_on_device``, returning a
    :class:`DeviceTrace`)."""

    n_triangles: int
    variant: str  # the Mitsuba variant that traces it

    def trace(
        self, radar: RadarConfig, pose: np.ndarray | None = None, *, seed: int | None = None
    ) -> TraceResult:
        """The frame's binned returns (``fidelity: raytrace``)."""
        ...

    def trace_paths(
        self,
        radar: RadarConfig,
        pose: np.ndarray | None = None,
        *,
        seed: int | None = None,
        velocity_mps: np.ndarray | None = None,
    ) -> PathSet:
        """The frame's propagation paths (``fidelity: signal``)."""
        ...


def simulate_scene_frame(
    scene: TracedScene,
    radar: RadarConfig,
    pose: np.ndarray | None = None,
    *,
    return_cube: bool = False,
    seed: int | None = None,
    velocity_mps: np.ndarray | None = None,
    device: Any = "auto",
) -> RadarFrame:
    """Simulate one frame of a pre-built scene (a :class:`~sim2radar.radar.raytrace.RadarScene`;
    parameters as for :func:`sim2radar.radar.simulate_frame`).

    ``device`` (``raytrace`` fidelity, ``integrated`` detection): ``"auto"`` picks
    :func:`detection_device` of the scene's variant; ``None`` detects on the host in NumPy; a
    torch device (``"cpu"``, ``"cuda"``) traces into torch tensors
    (:meth:`~sim2radar.radar.raytrace.RadarScene.trace_on_device`) and detects there
    (:func:`sim2radar.radar.detection_torch.detect_frame`; its noise is a torch stream)."""
    if radar.fidelity == "signal":
        return _simulate_signal_scene_frame(scene, radar, pose, seed=seed,
                                            velocity_mps=velocity_mps)
    if isinstance(device, str) and device == "auto":
        device = detection_device(scene.variant)
    if radar.detection.domain != "integrated":
        device = None
    t0 = time.perf_counter()
    noise_added = seed is not None and radar.detection.add_noise
    if device is not None:
        result = scene.trace_on_device(radar, pose, seed=seed)
    else:
        result = scene.trace(radar, pose, seed=seed)
    t1 = time.perf_counter()
    geom = array_geometry(radar)
    n0 = cell_noise_power(radar)
    cube = None
    if return_cube:
        host = result.accumulator if device is None else result.accumulator.to_host()
        aperture = host.aperture(geom)
        if noise_added:
            aperture = add_receiver_noise(aperture, geom, n0,
                                          np.random.default_rng([int(seed), CUBE_NOISE_STREAM]))
        cube = beamform(aperture, geom)
    t2 = time.perf_counter()
    # receiver noise per virtual channel (binning.add_receiver_noise), from its own stream
    # (the ray jitter draws from default_rng(seed))
    if device is None:
        rng = np.random.default_rng([int(seed), NOISE_STREAM]) if noise_added else None
        found = detect_frame(result.accumulator, radar, velocity_mps=velocity_mps, rng=rng)
    else:
        from sim2radar.radar import detection_torch

        gen = (detection_torch.noise_generator(int(seed), NOISE_STREAM,
                                               result.accumulator.device)
               if noise_added else None)
        found = detection_torch.detect_frame(result.accumulator, radar,
                                             velocity_mps=velocity_mps, generator=gen)
    points = found.points
    t3 = time.perf_counter()
    seconds = dict(result.seconds)
    seconds["beamform"] = t2 - t1
    seconds["detect"] = t3 - t2
    seconds["total"] = t3 - t0
    stats = {
        "fidelity": radar.fidelity,
        "max_range_m": radar.max_range_m,
        "n_rays": result.n_rays,
        "n_hits": result.hits_per_bounce[0] if result.hits_per_bounce else 0,
        "hits_per_bounce": list(result.hits_per_bounce),
        "n_points": int(len(points)),
        "n_triangles": scene.n_triangles,
        "variant": scene.variant,
        "seed": seed,
        "noise_power_per_cell": n0,
        "noise_added": noise_added,
        "detection_device": "host" if device is None else str(device),
        "rig_velocity_mps": (None if velocity_mps is None
                             else [float(v) for v in np.asarray(velocity_mps).reshape(3)]),
        "seconds": seconds,
    }
    return RadarFrame(
        points=points,
        doppler_mps=found.doppler_mps,
        cube=cube,
        range_bins_m=radar.range_bins_m,
        azimuth_bins_rad=radar.azimuth_bins_rad,
        elevation_bins_rad=radar.elevation_bins_rad,
        stats=stats,
    )


def _simulate_signal_scene_frame(
    scene: TracedScene, radar: RadarConfig, pose: np.ndarray | None, *, seed: int | None,
    velocity_mps: np.ndarray | None = None,
) -> RadarFrame:
    """``fidelity: signal``: trace propagation paths, synthesise IF samples, run the chain."""
    from sim2radar.radar.signal import simulate_signal_frame

    t0 = time.perf_counter()
    paths = scene.trace_paths(radar, pose, seed=seed, velocity_mps=velocity_mps)
    t1 = time.perf_counter()
    sf = simulate_signal_frame(paths, radar, seed=seed, heatmap=False)  # points only
    t2 = time.perf_counter()
    stats = {
        "fidelity": radar.fidelity,
        "max_range_m": radar.max_range_m,
        "n_paths": int(len(paths)),
        "n_points": sf.n_points,
        "n_triangles": scene.n_triangles,
        "variant": scene.variant,
        **{k: v for k, v in sf.stats.items() if not k.startswith("seconds")},
        "seed": seed,
        "seconds": {"trace": t1 - t0, "signal": t2 - t1, "total": t2 - t0,
                    **{k.removeprefix("seconds_"): v for k, v in sf.stats.items()
                       if k.startswith("seconds_") and k != "seconds_total"}},
    }
    points = np.ascontiguousarray(sf.points[:, :4], dtype=np.float32)
    return RadarFrame(
        points=points,
        doppler_mps=np.ascontiguousarray(sf.points[:, 4], dtype=np.float32),
        cube=None,
        range_bins_m=np.asarray(sf.range_m, np.float32),
        azimuth_bins_rad=np.arcsin(np.clip(sf.azimuth_sin, -1.0, 1.0)).astype(np.float32),
        elevation_bins_rad=radar.elevation_bins_rad,
        stats=stats,
    )
