"""Radar simulation: RadarConfig + presets, Mitsuba/Dr.Jit ray tracer, coherent binning, CFAR.

Public API::

    from sim2radar.radar import load_radar_config, simulate_frame, RadarScene
    radar = load_radar_config("ti-mmwcas")
    frame = simulate_frame(meshes, radar, pose=None)      # frame.points (N, 4) float32
    scene = RadarScene(meshes)                             # build once, many poses:
    frames = [scene.simulate(radar, pose) for pose in poses]
"""

from sim2radar.radar.binning import Accumulator, accumulate, bin_indices
from sim2radar.radar.config import (
    DetectionConfig,
    RadarConfig,
    RadarConfigError,
    ScatteringConfig,
    load_radar_config,
    preset_names,
)
from sim2radar.radar.detection import ca_cfar_mask, detect_points, spherical_to_cartesian
from sim2radar.radar.frame import RadarFrame, simulate_frame, simulate_scene_frame
from sim2radar.radar.raytrace import RadarScene, TraceResult, check_pose, merge_meshes

__all__ = [
    "Accumulator",
    "DetectionConfig",
    "RadarConfig",
    "RadarConfigError",
    "RadarFrame",
    "RadarScene",
    "ScatteringConfig",
    "TraceResult",
    "accumulate",
    "bin_indices",
    "ca_cfar_mask",
    "check_pose",
    "detect_points",
    "load_radar_config",
    "merge_meshes",
    "preset_names",
    "simulate_frame",
    "simulate_scene_frame",
    "spherical_to_cartesian",
]
