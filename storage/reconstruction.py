"""Parquet artifacts of the reconstruction stage (a :class:`~sim2radar.reconstruct.LabeledScene`).

Two artifacts per frame, both keyed by ``content_key(stage, STAGE_VERSION, inputs={"image":
digest of the RGB [+ LiDAR]}, config=resolved ReconstructionConfig + target frame)``:

* ``scene_meshes`` (declared in ``storage/schemas.py``): the per-segment meshes in the target
  frame (level frame by default: a radar at the camera with ``pose=None``), ready for the radar
  simulation flow.
* ``reconstruction`` (declared in ``storage/schemas.py``): one row per frame with the per-pixel maps
  (depth, segment, semantic and material ids), segment labels/materials/confidences/reasons,
  door boxes, the level frame and timings.

"""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa

from sim2radar.camera import CameraIntrinsics
from sim2radar.fileio import jsonable
from sim2radar.storage.codecs import meshes_to_table
from sim2radar.storage.keys import bytes_digest, content_key
from sim2radar.storage.schemas import RECONSTRUCTION as RECONSTRUCTION_SCHEMA

__all__ = ["RECONSTRUCTION_SCHEMA", "scene_to_tables", "write_scene_artifacts",
           "read_reconstruction", "frame_digest", "reconstruction_keys", "depth_to_table",
           "depth_from_table", "segments_to_table", "segments_from_table", "materials_to_table",
           "materials_from_table", "frame_input_digests", "stage_keys"]



def frame_digest(rgb: np.ndarray, lidar_points: np.ndarray | None = None,
                 rig_calibration: dict | None = None) -> str:
    """Content digest of a frame's inputs (RGB bytes [+ LiDAR bytes] [+ the rig calibration,
    ``FrameInput.rig_calibration``, when it has one])."""
    data = np.ascontiguousarray(rgb, np.uint8).tobytes()
    if lidar_points is not None:
        data += np.ascontiguousarray(lidar_points, np.float32).tobytes()
    if rig_calibration:
        data += json.dumps({k: np.round(np.asarray(v, np.float64), 9).tolist()
                            for k, v in rig_calibration.items()}, sort_keys=True).encode()
    return bytes_digest(data)


def scene_to_tables(scene, camera_to_target: np.ndarray | None = None) -> dict[str, pa.Table]:
    """``{"scene_meshes": ..., "reconstruction": ...}`` for one :class:`LabeledScene`.

    ``camera_to_target`` (4, 4) maps camera -> target frame of meshes and boxes; ``None`` means
    the level frame.
    """
    m = scene.level_from_camera if camera_to_target is None else np.asarray(camera_to_target)
    k: CameraIntrinsics = scene.intrinsics
    mats = scene.segment_materials
    row = {
        "name": [scene.name],
        "width": [k.width], "height": [k.height],
        "intrinsics": [[k.fx, k.fy, k.cx, k.cy]],
        "depth_m": [np.asarray(scene.depth_m, np.float32).ravel()],
        "segment_id": [np.asarray(scene.segment_id, np.int32).ravel()],
        "semantic_id": [np.asarray(scene.semantic_id, np.uint8).ravel()],
        "material_id": [np.asarray(scene.material_id, np.uint8).ravel()],
        "segment_labels": [list(scene.segment_labels)],
        "segment_scores": [np.asarray(scene.segment_scores, np.float32)],
        "segment_materials": [[x.material for x in mats]],
        "material_confidence": [np.array([x.confidence for x in mats], np.float32)],
        "material_reasons": [[x.reason for x in mats]],
        "door_boxes": [scene.door_boxes_in(camera_to_target).astype(np.float32).tolist()],
        "camera_to_target": [np.asarray(m, np.float64).ravel()],
        "level_from_camera": [np.asarray(scene.level_from_camera, np.float64).ravel()],
        "floor_z_m": [float(scene.floor_z_m)],
        "timings_s": [list(scene.timings_s.items())],
        "info_json": [json.dumps(jsonable(scene.info, max_array=16), sort_keys=True)],
    }
    table = pa.Table.from_pydict(
        {name: pa.array(v, type=RECONSTRUCTION_SCHEMA.schema.field(name).type)
         for name, v in row.items()})
    return {"scene_meshes": meshes_to_table(scene.meshes_in(camera_to_target)),
            "reconstruction": table}


def frame_input_digests(frame) -> dict[str, str]:
    """Input digests of a :class:`~sim2radar.reconstruct.FrameInput` read from files (the
    ``reconstruct`` flow and the capture factory): ``image`` (RGB [+ LiDAR] bytes) and
    ``intrinsics`` (fx, fy, cx, cy, width, height + the rig calibration)."""
    k = frame.intrinsics
    kk = np.asarray([[k.fx, k.fy, k.cx, k.cy, k.width, k.height]], np.float32)
    return {"image": frame_digest(frame.rgb, frame.lidar_points),
            "intrinsics": frame_digest(kk, rig_calibration=frame.rig_calibration)}


#: Reconstruction settings applied after one view's reconstruction (multi-view fusion,
#: :mod:`sim2radar.reconstruct.fusion`): they change no per-view artifact, so its keys leave them
#: out (the dataset frames that use them hash the whole config).
AFTER_THE_VIEW = ("fusion",)


def stage_keys(inputs: dict[str, str], config: dict, *, stage_version: int = 1) -> dict[str, str]:
    """Content keys of every artifact of one frame's reconstruction, stage by stage:
    ``depth_maps`` (inputs + depth backend), ``segmentations`` (+ depth key + segmenter),
    ``material_labels`` (+ segmentation key + material backend), and the final
    ``scene_meshes`` / ``reconstruction`` (level frame, :func:`reconstruction_keys`). A change
    of one backend re-keys its stage and the ones after it, not the ones before."""
    common = {"rig_calibration": config.get("rig_calibration", True),
              "max_depth_m": config.get("max_depth_m")}
    depth = content_key(stage="depth_maps", stage_version=stage_version, inputs=inputs,
                        config={"depth": config["depth"], **common})
    seg = content_key(stage="segmentations", stage_version=stage_version,
                      inputs={**inputs, "depth_maps": depth},
                      config={"segments": config["segments"], **common})
    mat = content_key(stage="material_labels", stage_version=stage_version,
                      inputs={**inputs, "depth_maps": depth, "segmentations": seg},
                      config={"materials": config["materials"], **common})
    return {"depth_maps": depth, "segmentations": seg, "material_labels": mat,
            **reconstruction_keys(inputs, config, stage_version=stage_version)}


def reconstruction_keys(inputs: dict[str, str], config: dict,
                        camera_to_target: np.ndarray | None = None, *,
                        stage_version: int = 1) -> dict[str, str]:
    """Content keys of a frame's ``scene_meshes`` and ``reconstruction`` artifacts: the one
    recipe every writer and reader uses (a cached reconstruction is found by computing these up
    front).

    Parameters
    ----------
    inputs : name -> digest of the frame's inputs (``{"image": frame_digest(...)}``).
    config : the resolved reconstruction config (``ReconstructionConfig.to_dict()``).
    camera_to_target : (4, 4) camera -> frame of the meshes and boxes; None: the level frame.
    stage_version : the reconstruction's ``STAGE_VERSION``.
    """
    frame_cfg = None if camera_to_target is None else np.asarray(camera_to_target).round(9).tolist()
    per_view = {k: v for k, v in config.items() if k not in AFTER_THE_VIEW}
    return {stage: content_key(stage=stage, stage_version=stage_version, inputs=inputs,
                               config={"reconstruction": per_view, "camera_to_target": frame_cfg})
            for stage in ("scene_meshes", "reconstruction")}


def write_scene_artifacts(store, scene, *, inputs: dict[str, str], config: dict,
                          camera_to_target: np.ndarray | None = None, seed: int | None = None,
                          stage_version: int = 1,
                          provisional: dict | None = None) -> dict[str, str]:
    """Write both artifacts of ``scene`` (skipping any that are cached) and return stage -> key;
    ``provisional`` (its materials fell back, :meth:`ArtifactStore.write`) marks both.

    Parameters
    ----------
    store : storage.ArtifactStore
    inputs : name -> content key/digest of the frame's inputs (e.g. ``{"image": frame_digest(...)}``).
    config : the resolved reconstruction config (``ReconstructionConfig.to_dict()``).
    """
    keys = reconstruction_keys(inputs, config, camera_to_target, stage_version=stage_version)
    frame_cfg = None if camera_to_target is None else "target"
    tables = None
    for stage, key in keys.items():
        if store.cached(stage, key):
            continue
        tables = tables or scene_to_tables(scene, camera_to_target)
        store.write(stage, key, tables[stage], stage_version=stage_version,
                    provisional=provisional,
                    provenance={"inputs": inputs, "config": config, "seed": seed,
                                "timings_s": dict(scene.timings_s),
                                "extra": {"frame": frame_cfg or "level",
                                          "name": scene.name}})
    return keys


def read_reconstruction(store, key: str) -> dict:
    """Read a ``reconstruction`` artifact back into arrays (maps reshaped to (H, W))."""
    t = store.read("reconstruction", key).to_pylist()[0]
    h, w = t["height"], t["width"]
    return {
        "name": t["name"],
        "intrinsics": CameraIntrinsics(*t["intrinsics"], w, h),
        "depth_m": np.asarray(t["depth_m"], np.float32).reshape(h, w),
        "segment_id": np.asarray(t["segment_id"], np.int32).reshape(h, w),
        "semantic_id": np.asarray(t["semantic_id"], np.uint8).reshape(h, w),
        "material_id": np.asarray(t["material_id"], np.uint8).reshape(h, w),
        "segment_labels": t["segment_labels"],
        "segment_materials": t["segment_materials"],
        "material_confidence": np.asarray(t["material_confidence"], np.float32),
        "door_boxes": np.asarray(t["door_boxes"], np.float32).reshape(-1, 7),
        "camera_to_target": np.asarray(t["camera_to_target"]).reshape(4, 4),
        "level_from_camera": np.asarray(t["level_from_camera"]).reshape(4, 4),
        "timings_s": dict(t["timings_s"]),
        "info": json.loads(t["info_json"]),
    }


# ---------------------------------------------------------------------------------------------
# The reconstruction's stages one by one (``depth_maps``, ``segmentations``, ``material_labels``)
# ---------------------------------------------------------------------------------------------
def _schema_table(schema, row: dict) -> pa.Table:
    return pa.Table.from_pydict({name: pa.array([v], type=schema.schema.field(name).type)
                                 for name, v in row.items()})


def depth_to_table(name: str, depth, seconds: float) -> pa.Table:
    """One-row ``depth_maps`` table of a :class:`~sim2radar.reconstruct.DepthResult`."""
    from sim2radar.storage.schemas import DEPTH_MAPS

    d = np.asarray(depth.depth_m, np.float32)
    return _schema_table(DEPTH_MAPS, {
        "name": name, "width": d.shape[1], "height": d.shape[0], "depth_m": d.ravel(),
        "info_json": json.dumps(jsonable(depth.info, max_array=16), sort_keys=True),
        "seconds": float(seconds)})


def depth_from_table(table: pa.Table):
    """``(DepthResult, seconds)`` of a ``depth_maps`` table."""
    from sim2radar.reconstruct.types import DepthResult

    t = table.to_pylist()[0]
    depth = np.asarray(t["depth_m"], np.float32).reshape(t["height"], t["width"])
    return DepthResult(depth, json.loads(t["info_json"])), float(t["seconds"])


def segments_to_table(name: str, segments, seconds: float) -> pa.Table:
    """One-row ``segmentations`` table of a :class:`~sim2radar.reconstruct.Segments`."""
    from sim2radar.storage.schemas import SEGMENTATIONS

    ids = np.asarray(segments.segment_id, np.int32)
    return _schema_table(SEGMENTATIONS, {
        "name": name, "width": ids.shape[1], "height": ids.shape[0], "segment_id": ids.ravel(),
        "labels": list(segments.labels), "scores": np.asarray(segments.scores, np.float32),
        "up_cam": None if segments.up_cam is None else np.asarray(segments.up_cam, np.float64),
        "door_boxes_level": np.asarray(segments.door_boxes_level, np.float32).tolist(),
        "info_json": json.dumps(jsonable(segments.info, max_array=16), sort_keys=True),
        "seconds": float(seconds)})


def segments_from_table(table: pa.Table):
    """``(Segments, seconds)`` of a ``segmentations`` table."""
    from sim2radar.reconstruct.types import Segments

    t = table.to_pylist()[0]
    seg = Segments(np.asarray(t["segment_id"], np.int32).reshape(t["height"], t["width"]),
                   tuple(t["labels"]), np.asarray(t["scores"], np.float32),
                   up_cam=None if t["up_cam"] is None else np.asarray(t["up_cam"], np.float64),
                   door_boxes_level=np.asarray(t["door_boxes_level"], np.float32).reshape(-1, 7),
                   info=json.loads(t["info_json"]))
    return seg, float(t["seconds"])


def materials_to_table(name: str, labels, fallbacks, seconds: float) -> pa.Table:
    """One-row ``material_labels`` table of a list of
    :class:`~sim2radar.reconstruct.MaterialLabel` (one per segment)."""
    from sim2radar.storage.schemas import MATERIAL_LABELS

    return _schema_table(MATERIAL_LABELS, {
        "name": name, "materials": [x.material for x in labels],
        "confidence": np.array([x.confidence for x in labels], np.float32),
        "reasons": [x.reason for x in labels], "fallbacks": list(fallbacks),
        "seconds": float(seconds)})


def materials_from_table(table: pa.Table):
    """``(labels, fallbacks, seconds)`` of a ``material_labels`` table."""
    from sim2radar.reconstruct.types import MaterialLabel

    t = table.to_pylist()[0]
    labels = [MaterialLabel(m, float(c), r) for m, c, r in
              zip(t["materials"], t["confidence"], t["reasons"], strict=True)]
    return labels, list(t["fallbacks"]), float(t["seconds"])
