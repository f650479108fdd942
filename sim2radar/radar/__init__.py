"""Radar simulation: RadarConfig + presets, Mitsuba/Dr.Jit ray tracer, coherent binning, CFAR.

Public API::

    from sim2radar.radar import load_radar_config, simulate_frame, RadarScene
    radar = load_radar_config("ti-mmwcas")
    frame = simulate_frame(meshes, radar, pose=None)      # frame.points (N, 4) float32
    scene = RadarScene(meshes)                             # build once, many poses:
    frames = [scene.simulate(radar, pose) for pose in poses]
    paths = scene.trace_paths(radar, pose, seed=0)         # PathSet for signal-level synthesis
"""

from sim2radar.radar.binning import (
    Accumulator,
    ArrayGeometry,
    TraceResult,
    accumulate,
    array_geometry,
    beamform,
    bin_indices,
    deposit,
)
from sim2radar.radar.config import (
    DEFAULT_RADAR,
    DetectionConfig,
    RadarConfig,
    RadarConfigError,
    ScatteringConfig,
    load_radar_config,
    preset_names,
)
from sim2radar.radar.detection import (
    ca_cfar_mask,
    cell_noise_power,
    detect_points,
    direction_to_cartesian,
    spherical_to_cartesian,
)
from sim2radar.radar.frame import RadarFrame, TracedScene, simulate_scene_frame
from sim2radar.radar.paths import PATH_KINDS, PathSet
from sim2radar.radar.raytrace import (
    RadarScene,
    check_pose,
    face_object_ids,
    merge_meshes,
)
from sim2radar.radar.simulate import simulate_frame

__all__ = [
    "DEFAULT_RADAR",
    "Accumulator",
    "ArrayGeometry",
    "PATH_KINDS",
    "PathSet",
    "DetectionConfig",
    "RadarConfig",
    "RadarConfigError",
    "RadarFrame",
    "RadarScene",
    "ScatteringConfig",
    "TraceResult",
    "TracedScene",
    "accumulate",
    "array_geometry",
    "beamform",
    "bin_indices",
    "ca_cfar_mask",
    "cell_noise_power",
    "check_pose",
    "deposit",
    "detect_points",
    "direction_to_cartesian",
    "face_object_ids",
    "load_radar_config",
    "merge_meshes",
    "preset_names",
    "simulate_frame",
    "simulate_scene_frame",
    "spherical_to_cartesian",
]
