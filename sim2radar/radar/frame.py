"""``simulate_frame``: material meshes + radar config + pose -> radar point cloud (+ cube)."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from sim2radar.mesh import MaterialMesh
from sim2radar.radar.config import RadarConfig, load_radar_config
from sim2radar.radar.detection import detect_points
from sim2radar.radar.raytrace import RadarScene

__all__ = ["RadarFrame", "simulate_frame", "simulate_scene_frame"]


@dataclasses.dataclass(frozen=True, eq=False)
class RadarFrame:
    """One simulated radar frame.

    Attributes
    ----------
    points : (N, 4) float32
        x, y, z [m] in the radar frame (x forward, y left, z up), intensity [dB]
        (``10 log10(4 pi |a|^2)`` = RCS [dBsm] - 40 log10(range [m])), strongest first.
    cube : (n_range, n_az, n_el) complex64 or None
        Coherent range-azimuth-elevation returns (``return_cube=True``), noise included
        when a seed was given.
    range_bins_m : (n_range,) float32 — range bin centres [m].
    azimuth_bins_rad : (n_az,) float32 — azimuth bin centres [rad] (+ = left).
    elevation_bins_rad : (n_el,) float32 — elevation bin centres [rad] (+ = up).
    stats : dict
        ``n_rays``, ``n_hits`` (first bounce), ``hits_per_bounce``, ``n_points``,
        ``n_triangles``, ``variant``, ``seed`` and ``seconds`` per stage
        (``rays``, ``trace``, ``readback``, ``detect``, ``total``).
    """

    points: np.ndarray
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


def simulate_scene_frame(
    scene: RadarScene,
    radar: RadarConfig,
    pose: np.ndarray | None = None,
    *,
    return_cube: bool = False,
    seed: int | None = None,
) -> RadarFrame:
    """Simulate one frame of a pre-built :class:`RadarScene` (see :func:`simulate_frame`)."""
    t0 = time.perf_counter()
    result = scene.trace(radar, pose, seed=seed)
    t1 = time.perf_counter()
    shape = (radar.n_range_bins, radar.n_azimuth_bins, radar.n_elevation_bins)
    cube = result.accumulator.cube(shape)
    if seed is not None:
        # receiver noise: circular complex Gaussian, power N0 per cell
        rng = np.random.default_rng(seed)
        sigma = math.sqrt(10.0 ** (radar.detection.noise_floor_db / 10.0) / 2.0)
        cube = cube + (
            sigma * (rng.standard_normal(shape) + 1j * rng.standard_normal(shape))
        ).astype(np.complex64)
    points = detect_points(cube, result.accumulator, radar)
    t2 = time.perf_counter()
    seconds = dict(result.seconds)
    seconds["detect"] = t2 - t1
    seconds["total"] = t2 - t0
    stats = {
        "n_rays": result.n_rays,
        "n_hits": result.hits_per_bounce[0] if result.hits_per_bounce else 0,
        "hits_per_bounce": list(result.hits_per_bounce),
        "n_points": int(len(points)),
        "n_triangles": scene.n_triangles,
        "variant": scene.variant,
        "seed": seed,
        "seconds": seconds,
    }
    return RadarFrame(
        points=points,
        cube=cube if return_cube else None,
        range_bins_m=radar.range_bins_m,
        azimuth_bins_rad=radar.azimuth_bins_rad,
        elevation_bins_rad=radar.elevation_bins_rad,
        stats=stats,
    )


def simulate_frame(
    meshes: Sequence[MaterialMesh] | RadarScene,
    radar: RadarConfig | str,
    pose: np.ndarray | None = None,
    *,
    return_cube: bool = False,
    seed: int | None = None,
) -> RadarFrame:
    """Simulate one radar frame of a material-labelled scene.

    Parameters
    ----------
    meshes : list of MaterialMesh (or a pre-built RadarScene)
        Scene in the world frame [m]. To simulate many poses of one scene, build
        ``RadarScene(meshes)`` once and pass it (or call ``scene.simulate``).
    radar : RadarConfig or str
        A config, or a preset name / YAML path for :func:`load_radar_config`.
    pose : (4, 4) array, optional
        Radar-to-world rigid transform; ``None`` = identity (meshes given in the radar frame:
        x forward, y left, z up).
    return_cube : bool
        Also return the complex (n_range, n_az, n_el) cube.
    seed : int, optional
        ``None``: deterministic regular ray grid and no random receiver noise. An integer
        jitters the rays within their grid cells, re-draws the diffuse speckle phases and adds
        complex Gaussian receiver noise at ``detection.noise_floor_db`` — reproducibly.

    Returns
    -------
    RadarFrame
    """
    radar = radar if isinstance(radar, RadarConfig) else load_radar_config(radar)
    scene = meshes if isinstance(meshes, RadarScene) else RadarScene(meshes)
    return simulate_scene_frame(scene, radar, pose, return_cube=return_cube, seed=seed)
