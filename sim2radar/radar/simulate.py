"""``simulate_frame``: material meshes + radar config + pose -> radar point cloud (+ cube).

The one-call entry point: it builds the ray tracer's :class:`~sim2radar.radar.raytrace.RadarScene`
(unless given one) and simulates one frame of it (:func:`sim2radar.radar.frame.simulate_scene_frame`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim2radar.mesh import MaterialMesh
from sim2radar.radar.config import RadarConfig
from sim2radar.radar.frame import RadarFrame
from sim2radar.radar.raytrace import RadarScene

__all__ = ["simulate_frame"]


def simulate_frame(
    meshes: Sequence[MaterialMesh] | RadarScene,
    radar: RadarConfig | str,
    pose: np.ndarray | None = None,
    *,
    return_cube: bool = False,
    seed: int | None = None,
    velocity_mps: np.ndarray | None = None,
) -> RadarFrame:
    """Simulate one radar frame of a material-labelled scene.

    Parameters
    ----------
    meshes : list of MaterialMesh (or a pre-built RadarScene)
        Scene in the world frame [m]. To simulate many poses of one scene, build
        ``RadarScene(meshes)`` once and pass it (or call ``scene.simulate``).
    radar : RadarConfig or str
        A config, or a preset name / YAML path for
        :func:`~sim2radar.radar.config.load_radar_config`.
    pose : (4, 4) array, optional
        Radar-to-world rigid transform; ``None`` = identity (meshes given in the radar frame:
        x forward, y left, z up).
    return_cube : bool
        Also return the complex (n_range, n_az, n_el) cube.
    seed : int, optional
        ``None``: deterministic regular ray grid, fixed speckle phases and no receiver noise
        (detection thresholds still use the noise level). An integer jitters the rays within
        their grid cells, re-draws the speckle phases and (``detection.add_noise``, default on)
        adds complex Gaussian receiver noise to every virtual channel at the level of
        :func:`sim2radar.radar.detection.cell_noise_power` (the hardware link budget unless
        ``detection.noise_floor_db`` overrides it) — reproducibly.
    velocity_mps : (3,), optional
        The radar's velocity in its own frame [m/s] over a static scene (None: standing
        still). The signal-level radar (``fidelity: signal``) turns it into each path's range
        rate and so into Doppler; the ray tracer's ``integrated`` detector separates its
        returns into Doppler bins by direction with it
        (:func:`sim2radar.radar.detection.doppler_bins`), as the device's range-Doppler map
        does.

    Returns
    -------
    RadarFrame
    """
    scene = meshes if isinstance(meshes, RadarScene) else RadarScene(meshes)
    return scene.simulate(radar, pose, return_cube=return_cube, seed=seed,
                          velocity_mps=velocity_mps)
