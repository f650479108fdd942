"""Helpers for the flow/task tests: tiny scene files written on the fly."""

from __future__ import annotations

from pathlib import Path

import yaml

from sim2radar.mesh import box_mesh, save_ply

#: Radar pose of the plate scene: at (1, 2, 1) m, looking along world +y (yaw 90°).
RADAR_POSITION = (1.0, 2.0, 1.0)
RADAR_YAW_DEG = 90.0
PLATE_RANGE_M = 3.0


def write_scene(folder: Path, name: str, objects, poses=None, boxes=None) -> Path:
    """Write meshes as PLY + a scene YAML; ``objects`` = (name, material, centre, size)."""
    folder.mkdir(parents=True, exist_ok=True)
    entries = []
    for obj_name, material, centre, size in objects:
        save_ply(box_mesh(centre, size, material=material), folder / f"{obj_name}.ply")
        entries.append({"file": f"{obj_name}.ply", "material": material, "name": obj_name})
    doc = {"name": name, "meshes": entries}
    if poses is not None:
        doc["radar_poses"] = poses
    if boxes is not None:
        doc["boxes"] = boxes
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


