"""The dataset factory's own logic, independent of Prefect: labelling rules (door visibility to
the radar, the detector's range filter), seed recipes and the reference-radar frame pipeline.
``tasks/`` wraps these with caching and store I/O; ``flows/`` composes the tasks."""

from sim2radar.factory.labels import (
    LabelConfig,
    boxes_in_point_cloud_range,
    doorway_samples,
    radar_visibility,
    scene_ray_caster,
)
from sim2radar.factory.seeds import frame_seed

__all__ = [
    "LabelConfig",
    "boxes_in_point_cloud_range",
    "doorway_samples",
    "frame_seed",
    "radar_visibility",
    "scene_ray_caster",
]
