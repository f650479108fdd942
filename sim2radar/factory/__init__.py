"""The dataset factory's own logic, independent of Prefect and of the store: the run
specification (:mod:`.spec`), labelling rules (door visibility to the radar, the detector's
range filter: :mod:`.labels`), seed recipes (:mod:`.seeds`), dataset frames (:mod:`.frames`),
the capture folder and radar poses in reconstructed free space (:mod:`.captures`) and the
reference radar (:mod:`.reference`). ``tasks/`` wraps these with keys, caching, store I/O and
outcome records; ``flows/`` composes the tasks."""

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
