"""Arrow tables for worlds and rendered frames (schemas ``world_specs`` and ``world_frames`` in
``storage/schemas.py``); the geometry itself goes to ``scene_meshes``.

Encodings (lossless unless noted):

* RGB: 8-bit PNG. Semantic/material ids: 8-bit PNG. Instance ids: 16-bit PNG of ``id + 1``.
* Depth: little-endian float16, row-major, with ``depth_min_m``/``depth_max_m`` alongside;
  relative precision 2^-11 (about 5 mm at 10 m) — lossy by design.
* Normals: 8-bit PNG of ``(n + 1) * 127.5`` (about 0.5° resolution) — lossy; decoded normals
  are re-normalised.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pyarrow as pa

from sim2radar.camera import CameraIntrinsics
from sim2radar.storage.codecs import ragged_arrays, ragged_column
from sim2radar.worlds.frame import World, WorldFrame, world_id_for

# world_id_for is the library's (sim2radar.worlds); named here too for the callers that take it
# from the tables' module
__all__ = ["world_spec_to_table", "frames_to_table", "frames_from_table", "encode_png",
           "decode_png", "world_id_for"]


def encode_png(image: np.ndarray) -> bytes:
    """PNG bytes of a (H, W) or (H, W, 3) uint8/uint16 array (RGB order for colour)."""
    import cv2

    img = np.ascontiguousarray(image)
    if img.ndim == 3:
        img = img[..., ::-1]  # OpenCV writes BGR
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise ValueError(f"PNG encoding failed for an array of shape {image.shape} {image.dtype}")
    return buf.tobytes()


def decode_png(data: bytes) -> np.ndarray:
    """Inverse of :func:`encode_png` (keeps the bit depth; colour comes back as RGB)."""
    import cv2

    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError("not a PNG image")
    return img[..., ::-1].copy() if img.ndim == 3 else img


def _ragged(arrays, value_type):
    return ragged_column(arrays, value_type)


def world_spec_to_table(world: World) -> pa.Table:
    """One-row ``world_specs`` table of ``world``."""
    objs = world.objects
    cfg = world.config.model_dump() if hasattr(world.config, "model_dump") else world.config
    return pa.table({
        "world_id": [world_id_for(world.seed)],
        "seed": pa.array([world.seed], pa.int64()),
        "layout": [world.layout],
        "ceiling_height_m": [world.ceiling_height_m],
        "spaces_json": [json.dumps([dataclasses.asdict(s) for s in world.spaces])],
        "doors_json": [json.dumps([dataclasses.asdict(d) for d in world.doors])],
        "door_boxes_world": _ragged([world.door_boxes_world.reshape(-1, 7)], pa.float32()),
        "object_names": [[o.name for o in objs]],
        "object_semantics": [[o.semantic for o in objs]],
        "object_materials": [[o.material for o in objs]],
        "object_kinds": [[o.kind for o in objs]],
        "object_door_index": pa.array([[o.door_index for o in objs]], pa.list_(pa.int32())),
        "object_space_index": pa.array([[o.space_index for o in objs]], pa.list_(pa.int32())),
        "appearances_json": [json.dumps([o.appearance.to_dict() for o in objs])],
        "path_world_m": _ragged([world.path_world.reshape(-1, 2)], pa.float64()),
        "config_json": [json.dumps(cfg, sort_keys=True)],
    })


def frames_to_table(frames: list[WorldFrame], world_id: str | None = None) -> pa.Table:
    """A ``world_frames`` table, one row per frame."""
    if not frames:
        raise ValueError("frames_to_table: no frames")
    rows: dict[str, list] = {k: [] for k in (
        "rgb_png", "depth_f16", "depth_min_m", "depth_max_m", "normals_png", "instance_png",
        "semantic_png", "material_png")}
    for f in frames:
        valid = f.depth_m > 0
        rows["rgb_png"].append(encode_png(f.rgb))
        rows["depth_f16"].append(f.depth_m.astype("<f2").tobytes())
        rows["depth_min_m"].append(float(f.depth_m[valid].min()) if valid.any() else 0.0)
        rows["depth_max_m"].append(float(f.depth_m.max()))
        n8 = np.clip(np.round((f.normals + 1.0) * 127.5), 0, 255).astype(np.uint8)
        rows["normals_png"].append(encode_png(n8))
        rows["instance_png"].append(encode_png((f.instance_id + 1).astype(np.uint16)))
        rows["semantic_png"].append(encode_png(f.semantic_id))
        rows["material_png"].append(encode_png(f.material_id))

    def mats(name):
        return pa.array([np.asarray(getattr(f, name), np.float64).ravel() for f in frames],
                        pa.list_(pa.float64(), 16))

    k = [f.intrinsics for f in frames]
    return pa.table({
        "world_id": [world_id or world_id_for(f.seed) for f in frames],
        "seed": pa.array([f.seed for f in frames], pa.int64()),
        "frame_index": pa.array([f.frame_index for f in frames], pa.int32()),
        "width": pa.array([i.width for i in k], pa.int32()),
        "height": pa.array([i.height for i in k], pa.int32()),
        "fx": [i.fx for i in k], "fy": [i.fy for i in k],
        "cx": [i.cx for i in k], "cy": [i.cy for i in k],
        "rgb_png": pa.array(rows["rgb_png"], pa.binary()),
        "depth_f16": pa.array(rows["depth_f16"], pa.binary()),
        "depth_min_m": pa.array(rows["depth_min_m"], pa.float32()),
        "depth_max_m": pa.array(rows["depth_max_m"], pa.float32()),
        "normals_png": pa.array(rows["normals_png"], pa.binary()),
        "instance_png": pa.array(rows["instance_png"], pa.binary()),
        "semantic_png": pa.array(rows["semantic_png"], pa.binary()),
        "material_png": pa.array(rows["material_png"], pa.binary()),
        "lidar_points_cam_m": _ragged([f.lidar_points.reshape(-1, 3) for f in frames],
                                      pa.float32()),
        "lidar_ring": _ragged([f.lidar_ring for f in frames], pa.uint8()),
        "camera_to_world": mats("camera_to_world"),
        "radar_to_world": mats("radar_to_world"),
        "lidar_to_world": mats("lidar_to_world"),
        "rig_to_world": mats("rig_to_world"),
        "lidar_to_camera": mats("lidar_to_camera"),
        "door_boxes_world": _ragged([f.door_boxes_world.reshape(-1, 7) for f in frames],
                                    pa.float32()),
        "door_boxes_radar": _ragged([f.door_boxes_radar.reshape(-1, 7) for f in frames],
                                    pa.float32()),
        "door_visible": _ragged([f.door_visible for f in frames], pa.bool_()),
        "door_visible_pixels": _ragged([f.door_visible_pixels for f in frames], pa.int32()),
        "door_in_fov": _ragged([f.door_in_fov for f in frames], pa.bool_()),
        "door_in_range": _ragged([f.door_in_range for f in frames], pa.bool_()),
        "render_seconds": [float(f.timings_s.get("total_s", 0.0)) for f in frames],
    })


def frames_from_table(table: pa.Table) -> list[WorldFrame]:
    """Decode a ``world_frames`` table back into :class:`WorldFrame` objects (depth and normals
    at their stored precision)."""
    lidar = ragged_arrays(table.column("lidar_points_cam_m"))
    ring = ragged_arrays(table.column("lidar_ring"))
    listed = {name: ragged_arrays(table.column(name)) for name in (
        "door_boxes_world", "door_boxes_radar", "door_visible", "door_visible_pixels",
        "door_in_fov", "door_in_range")}
    out = []
    for r in range(table.num_rows):
        def get(name, r=r):
            return table.column(name)[r].as_py()

        h, w = get("height"), get("width")
        k = CameraIntrinsics(get("fx"), get("fy"), get("cx"), get("cy"), w, h)
        depth = np.frombuffer(get("depth_f16"), "<f2").reshape(h, w).astype(np.float32)
        n = decode_png(get("normals_png")).astype(np.float32) / 127.5 - 1.0
        norm = np.linalg.norm(n, axis=-1, keepdims=True)
        n = np.where(depth[..., None] > 0, n / np.maximum(norm, 1e-6), 0.0).astype(np.float32)

        def mat(name, r=r):
            return np.asarray(table.column(name)[r].as_py(), np.float64).reshape(4, 4)

        out.append(WorldFrame(
            rgb=decode_png(get("rgb_png")),
            depth_m=depth,
            normals=n,
            instance_id=decode_png(get("instance_png")).astype(np.int32) - 1,
            semantic_id=decode_png(get("semantic_png")),
            material_id=decode_png(get("material_png")),
            lidar_points=np.asarray(lidar[r], np.float32).reshape(-1, 3),
            lidar_ring=np.asarray(ring[r], np.uint8),
            intrinsics=k,
            camera_to_world=mat("camera_to_world"),
            radar_to_world=mat("radar_to_world"),
            lidar_to_world=mat("lidar_to_world"),
            rig_to_world=mat("rig_to_world"),
            lidar_to_camera=mat("lidar_to_camera"),
            door_boxes_world=np.asarray(listed["door_boxes_world"][r], np.float64).reshape(-1, 7),
            door_boxes_radar=np.asarray(listed["door_boxes_radar"][r], np.float64).reshape(-1, 7),
            door_visible=np.asarray(listed["door_visible"][r], bool),
            door_visible_pixels=np.asarray(listed["door_visible_pixels"][r], np.int32),
            door_in_fov=np.asarray(listed["door_in_fov"][r], bool),
            door_in_range=np.asarray(listed["door_in_range"][r], bool),
            seed=int(get("seed")),
            frame_index=int(get("frame_index")),
            timings_s={"total_s": float(get("render_seconds"))},
        ))
    return out
