"""The reconstruction pipeline (paper §3): RGB [+ LiDAR] -> material-labelled 3D scene.

    from sim2radar.reconstruct import ReconstructionConfig, reconstruct, FrameInput

    config = ReconstructionConfig()                       # lidar depth, builtin segments, prior
    scene = reconstruct(FrameInput(rgb, intrinsics, lidar_points), config)
    meshes = scene.meshes_in(radar_from_camera)           # ready for sim2radar.radar.simulate_frame
    scene.door_boxes_in(radar_from_camera)                # (M, 7) pseudo-labels, radar frame

Stages and their backends are chosen by name (registries in :mod:`.types`); ``oracle`` backends
receive ``ground_truth`` (a ``WorldFrame`` or a dict of arrays). Stage 4 (back-projection,
per-segment meshes, door boxes) has no backends. Every stage is timed; fallbacks (e.g. a mesh
whose material is ``unknown`` given ``unknown_material`` for the radar) are recorded in
``LabeledScene.info["fallbacks"]``.
"""

from __future__ import annotations

import dataclasses
import logging
import time
import typing
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, create_model, field_validator

from sim2radar.camera import CameraIntrinsics
from sim2radar.configio import config_path, looks_like_path, read_yaml_mapping
from sim2radar.hardware import drjit_serial
from sim2radar.mesh import MaterialMesh, save_ply
from sim2radar.reconstruct.backproject import (
    gravity_up,
    level_from_camera,
    normals_from_points,
    points_from_depth,
)
from sim2radar.reconstruct.door_template import DoorTemplateConfig, door_template_meshes
from sim2radar.reconstruct.doors import (
    DoorFitConfig,
    dedupe_boxes,
    fit_door_boxes,
    plausible_door_boxes,
    transform_boxes,
)
from sim2radar.reconstruct.fusion import FusionConfig
from sim2radar.reconstruct.meshing import MeshingConfig, segment_meshes
from sim2radar.reconstruct.types import (
    DEPTH_BACKENDS,
    MATERIAL_BACKENDS,
    SEGMENT_BACKENDS,
    DepthResult,
    FrameInput,
    MaterialLabel,
    ReconstructionInputError,
    Segments,
)
from sim2radar.vocab import MATERIAL_CLASSES, SEMANTIC_CLASSES

__all__ = [
    "BackendSpec",
    "ReconstructionConfig",
    "LabeledScene",
    "reconstruct",
    "estimate_depth",
    "segment_image",
    "label_materials",
    "build_scene",
    "build_backends",
]

log = logging.getLogger(__name__)

#: Version of the reconstruction stage's output; part of artifact content keys. Bump when the
#: output of the same inputs and config changes (2: LiDAR depth completed down to the floor;
#: 3: the rig calibration, furniture fronts up to door height; 4: door height ≤ 2.3 m, double
#: doors, front-most wall faces, glass door leaves; 5: doorway boxes from the wall face measured
#: around the doorway, doorways from 0.78 m wide, openings framed by coplanar wall regions;
#: 6: boxes outside the doorway widths DoorFitConfig.min/max_width_m dropped, the door template:
#: casing, lever handle and hinges at every door box).
STAGE_VERSION = 6


class BackendSpec(BaseModel):
    """A backend chosen by registry name, with its keyword options."""

    model_config = ConfigDict(frozen=True, extra="forbid")
    name: str
    options: dict[str, Any] = Field(default_factory=dict)


def _options_model(name: str, config_cls: type, doc: str, *, exclude_from_config=(),
                   **overrides: tuple[Any, Any] | Any) -> type[BaseModel]:
    """A frozen, extra-forbidding pydantic model with the fields of the library dataclass
    ``config_cls`` (same names, types and defaults; ``overrides`` replace a default, or add a
    field as ``(type, default)``), and ``to_config()`` returning the dataclass."""
    hints = typing.get_type_hints(config_cls)
    fields: dict[str, Any] = {f.name: (hints[f.name], f.default)
                              for f in dataclasses.fields(config_cls)}
    for key, value in overrides.items():
        fields[key] = value if isinstance(value, tuple) else (fields[key][0], value)
    skip = set(exclude_from_config)

    def to_config(self):
        return config_cls(**self.model_dump(exclude=skip))

    model = create_model(name, __config__=ConfigDict(frozen=True, extra="forbid"),
                         __doc__=doc, **fields)
    model.to_config = to_config
    return model


MeshingOptions = _options_model(
    "MeshingOptions", MeshingConfig,
    "Meshing options in a config; fields and defaults of "
    ":class:`sim2radar.reconstruct.meshing.MeshingConfig`.")

DoorOptions = _options_model(
    "DoorOptions", DoorFitConfig,
    """Door-fitting options in a config; fields of :class:`sim2radar.reconstruct.doors.DoorFitConfig`
    with the pipeline's defaults: boxes snap to a floor within 0.8 m and get a 2.0 m doorway top.

    ``thickness_m`` (0.17 m) is the mean depth of the procedural worlds' doorway boxes (wall
    0.10–0.20 m + 2 cm, ``sim2radar/worlds/frame.py``): the box depth when it is not measured.
    ``nominal_width_m`` (0.95 m) is the width given to a door cut by the left/right image border
    when less of it is seen.""",
    exclude_from_config=("nominal_width_m",),
    snap_to_floor_m=0.8, min_top_m=2.0, nominal_width_m=(float, 0.95),
)


FusionOptions = _options_model(
    "FusionOptions", FusionConfig,
    """Multi-view fusion options in a config; fields and defaults of
    :class:`sim2radar.reconstruct.fusion.FusionConfig` (``frames: 0``: the current image
    only). Fusion happens after each view's own reconstruction, so it changes no per-view
    artifact (their content keys leave it out).""")

DoorTemplateOptions = _options_model(
    "DoorTemplateOptions", DoorTemplateConfig,
    """Door-template options in a config; fields and defaults of
    :class:`sim2radar.reconstruct.door_template.DoorTemplateConfig` (``enabled: false``: the
    paper's pipeline, door pixels only).""")


class ReconstructionConfig(BaseModel):
    """Typed configuration of :func:`reconstruct`.

    Attributes
    ----------
    depth, segments, materials : BackendSpec — registry name + options per stage.
    meshing : MeshingOptions; doors : DoorOptions; door_template : DoorTemplateOptions (casing,
        handle and hinges placed at each door box, :mod:`sim2radar.reconstruct.door_template`);
        fusion : FusionOptions (the previous frames of a scene added where the current camera
        does not look, :mod:`sim2radar.reconstruct.fusion`).
    max_depth_m : float [m] — depth beyond this is treated as invalid.
    unknown_material : str — material given to meshes whose label is ``unknown`` (the radar
        simulator needs a material); recorded as a fallback.
    rig_calibration : bool — use the rig calibration a frame carries
        (``FrameInput.up_cam``, ``camera_height_m``) for gravity and the floor; False ignores it
        (gravity from the image, the floor only where the LiDAR measures it).
    """

    model_config = ConfigDict(frozen=True, extra="forbid")
    depth: BackendSpec = BackendSpec(name="lidar")
    segments: BackendSpec = BackendSpec(name="builtin")
    materials: BackendSpec = BackendSpec(name="prior")
    meshing: MeshingOptions = MeshingOptions()
    doors: DoorOptions = DoorOptions()
    door_template: DoorTemplateOptions = DoorTemplateOptions()
    fusion: FusionOptions = FusionOptions()
    max_depth_m: float = 30.0
    unknown_material: str = "plasterboard"
    rig_calibration: bool = True

    @field_validator("unknown_material")
    @classmethod
    def _known_material(cls, v: str) -> str:
        if v not in MATERIAL_CLASSES or v == "unknown":
            raise ValueError(f"unknown_material must be one of {MATERIAL_CLASSES[1:]}, got {v!r}")
        return v

    @classmethod
    def from_yaml(cls, path: str | Path) -> ReconstructionConfig:
        """Load a YAML config; relative ``*path*`` options resolve against the file's folder —
        for a bundled config named without a path (``production``), against the working folder
        (your ``models/``, not the installed package's)."""
        bundled = not looks_like_path(path)
        path = config_path(path, "reconstruct", what="reconstruction config")
        # a bundled file names the checkout's folders (../../models/x.onnx from
        # configs/reconstruct/): the same path from the working folder (models/x.onnx)
        root = path.parent.parent.parent.resolve()

        def where(v: str) -> str:
            target = (path.parent / v).resolve()
            if bundled and target.is_relative_to(root):
                target = Path.cwd() / target.relative_to(root)
            return str(target)

        doc = read_yaml_mapping(path, what="reconstruction config",
                                missing_error=FileNotFoundError,
                                expect="a mapping (depth, segments, materials, ...)")
        for stage in ("depth", "segments", "materials"):
            spec = doc.get(stage)
            if isinstance(spec, str):
                doc[stage] = spec = {"name": spec}
            if isinstance(spec, dict):
                opts = spec.get("options") or {}
                for k, v in list(opts.items()):
                    if isinstance(v, str) and k.endswith("path") and not Path(v).is_absolute() \
                            and "://" not in v:
                        opts[k] = where(v)
        try:
            return cls.model_validate(doc)
        except Exception as exc:
            raise ValueError(f"{path}: invalid reconstruction config: {exc}") from exc

    @classmethod
    def preset(cls, name: str) -> ReconstructionConfig:
        """``builtin`` (lidar + builtin + prior, the default), ``oracle`` (all ground truth),
        ``builtin-oracle-depth`` (oracle depth + builtin segments + prior materials)."""
        presets = {
            "builtin": {},
            "oracle": {"depth": {"name": "oracle"}, "segments": {"name": "oracle"},
                       "materials": {"name": "oracle"}},
            "builtin-oracle-depth": {"depth": {"name": "oracle"}},
        }
        if name not in presets:
            raise ValueError(f"unknown reconstruction preset {name!r}; known: {sorted(presets)}")
        return cls.model_validate(presets[name])

    def to_dict(self) -> dict:
        """JSON-able resolved config (hashed into artifact keys)."""
        return self.model_dump(mode="json")


@dataclasses.dataclass(frozen=True, eq=False)
class LabeledScene:
    """A material-labelled 3D scene reconstructed from one frame.

    Attributes
    ----------
    name : str
    intrinsics : CameraIntrinsics
    rgb : (H, W, 3) uint8 — the input image.
    depth_m : (H, W) float32 — z-depth [m], 0 where invalid.
    points_cam : (H, W, 3) float32 — per-pixel points, camera frame (OpenCV) [m]; NaN invalid.
    segment_id : (H, W) int32 — segment per pixel, −1 unassigned.
    segment_labels : tuple[str, ...] — semantic class per segment.
    segment_scores : (S,) float32 — label confidence.
    segment_materials : tuple[MaterialLabel, ...] — material label per segment.
    semantic_id : (H, W) uint8 — per-pixel index into ``vocab.SEMANTIC_CLASSES``.
    material_id : (H, W) uint8 — per-pixel index into ``vocab.MATERIAL_CLASSES``.
    meshes : list[MaterialMesh] — one per segment, then the door template's (casing and
        hardware per door box, :mod:`sim2radar.reconstruct.door_template`), camera frame [m].
    door_boxes : (M, 7) float32 — ``x y z dx dy dz heading`` in the level frame.
    level_from_camera : (4, 4) float64 — camera frame -> level frame (x fwd, y left, z up).
    floor_z_m : float [m] — floor height in the level frame (NaN if no floor seen).
    timings_s : dict[str, float] — wall time per stage [s].
    info : dict — backend diagnostics and recorded fallbacks.
    """

    name: str
    intrinsics: CameraIntrinsics
    rgb: np.ndarray
    depth_m: np.ndarray
    points_cam: np.ndarray
    segment_id: np.ndarray
    segment_labels: tuple[str, ...]
    segment_scores: np.ndarray
    segment_materials: tuple[MaterialLabel, ...]
    semantic_id: np.ndarray
    material_id: np.ndarray
    meshes: list
    door_boxes: np.ndarray
    level_from_camera: np.ndarray
    floor_z_m: float
    timings_s: dict
    info: dict

    # -- frames ---------------------------------------------------------------------------
    def meshes_in(self, camera_to_target: np.ndarray | None = None) -> list[MaterialMesh]:
        """Meshes in another frame; ``camera_to_target`` (4, 4) maps camera -> target.

        ``None`` gives the level frame (x forward, y left, z up at the camera), which is the
        radar frame of a radar mounted at the camera: pass the result to
        ``simulate_frame(meshes, radar, pose=None)``. For a procedural world use
        ``inv(radar_to_world) @ camera_to_world`` to get the rig's radar frame.
        """
        m = self.level_from_camera if camera_to_target is None else np.asarray(camera_to_target)
        return [mesh.transformed(m) for mesh in self.meshes]

    def door_boxes_in(self, camera_to_target: np.ndarray | None = None) -> np.ndarray:
        """Door boxes (M, 7) in a z-up target frame (``None``: the level frame)."""
        if camera_to_target is None:
            return self.door_boxes.copy()
        level_to_target = np.asarray(camera_to_target) @ np.linalg.inv(self.level_from_camera)
        return transform_boxes(self.door_boxes, level_to_target)

    def points_in(self, camera_to_target: np.ndarray | None = None) -> np.ndarray:
        """Valid points (N, 3) float32 in the target frame (``None``: level frame)."""
        m = self.level_from_camera if camera_to_target is None else np.asarray(camera_to_target)
        p = self.points_cam[np.isfinite(self.points_cam).all(axis=-1)].astype(np.float64)
        return (p @ m[:3, :3].T + m[:3, 3]).astype(np.float32)

    @property
    def n_segments(self) -> int:
        return len(self.segment_labels)

    # -- exporters ------------------------------------------------------------------------
    def write_scene(self, out_dir: str | Path, camera_to_target: np.ndarray | None = None) -> Path:
        """Write the meshes as PLY files plus ``scene.yaml`` (``sim2radar.mesh.load_scene``
        format, so ``sim2radar simulate scene.yaml`` runs on it) and ``scene.xml`` (Mitsuba).

        Returns the path of ``scene.yaml``.
        """
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        entries = []
        for mesh in self.meshes_in(camera_to_target):
            save_ply(mesh, out / f"{mesh.name}.ply")
            entries.append({"file": f"{mesh.name}.ply", "material": mesh.material,
                            "semantic": mesh.semantic, "name": mesh.name})
        path = out / "scene.yaml"
        path.write_text(yaml.safe_dump({"meshes": entries}, sort_keys=False))
        (out / "scene.xml").write_text(mitsuba_xml(entries))
        return path

    @drjit_serial
    def to_mitsuba_dict(self, camera_to_target: np.ndarray | None = None) -> dict:
        """A Mitsuba scene dict with one in-memory ``mi.Mesh`` per segment (needs mitsuba; the
        variant comes from :func:`sim2radar.hardware.mitsuba_variant`). Each shape carries its
        material name as the BSDF id (``diffuse`` placeholder; the radar reads materials by
        name from the mesh list). A program that renders on other threads meanwhile should drop
        the dict through :func:`sim2radar.hardware.release_under_lock`."""
        import mitsuba as mi

        from sim2radar.hardware import mitsuba_variant, to_drjit

        mitsuba_variant()
        scene: dict[str, Any] = {"type": "scene"}
        for i, mesh in enumerate(self.meshes_in(camera_to_target)):
            m = mi.Mesh(mesh.name or f"mesh_{i}", len(mesh.vertices), len(mesh.faces))
            params = mi.traverse(m)
            params["vertex_positions"] = to_drjit(mi.Float, mesh.vertices.ravel(), np.float32)
            params["faces"] = to_drjit(mi.UInt32, mesh.faces.ravel(), np.uint32)
            params.update()
            scene[mesh.name or f"mesh_{i}"] = m
        return scene


def mitsuba_xml(entries: list[dict]) -> str:
    """Mitsuba 3 scene XML referencing PLY files (one shape per mesh, BSDF id = material)."""
    lines = ['<scene version="3.0.0">']
    for mat in sorted({e["material"] for e in entries}):
        lines.append(f'  <bsdf type="diffuse" id="{mat}"/>')
    for e in entries:
        lines.append(f'  <shape type="ply" id="{e["name"]}">')
        lines.append(f'    <string name="filename" value="{e["file"]}"/>')
        lines.append(f'    <ref id="{e["material"]}"/>')
        lines.append("  </shape>")
    lines.append("</scene>")
    return "\n".join(lines) + "\n"


def build_backends(config: ReconstructionConfig, ground_truth=None) -> tuple[Any, Any, Any]:
    """Instantiate the three stage backends named in ``config`` (``oracle`` ones get
    ``ground_truth``)."""
    import sim2radar.reconstruct  # noqa: F401  (registers every backend module)

    out = []
    for spec, registry in ((config.depth, DEPTH_BACKENDS), (config.segments, SEGMENT_BACKENDS),
                           (config.materials, MATERIAL_BACKENDS)):
        cls = registry.get(spec.name)
        kwargs = dict(spec.options)
        if spec.name == "oracle":
            kwargs["ground_truth"] = ground_truth
        try:
            out.append(cls(**kwargs))
        except TypeError as exc:
            raise ValueError(f"{registry.stage} backend {spec.name!r}: bad options {spec.options}: "
                             f"{exc}") from exc
    return tuple(out)


def _check_depth(frame: FrameInput, depth: DepthResult, max_depth_m: float) -> DepthResult:
    d = np.asarray(depth.depth_m, dtype=np.float32)
    if d.shape != frame.shape:
        raise ReconstructionInputError(
            f"{frame.name}: depth backend returned {d.shape}, image is {frame.shape}"
        )
    d = np.where(np.isfinite(d) & (d > 0) & (d <= max_depth_m), d, 0).astype(np.float32)
    if not (d > 0).any():
        raise ReconstructionInputError(
            f"{frame.name}: depth has no valid pixel (all 0/NaN or beyond max_depth_m="
            f"{max_depth_m}); check the depth backend and its input (LiDAR in view?)"
        )
    return DepthResult(d, dict(depth.info))


def _check_segments(frame: FrameInput, seg: Segments) -> Segments:
    ids = np.asarray(seg.segment_id)
    if ids.shape != frame.shape:
        raise ReconstructionInputError(
            f"{frame.name}: segmentation returned {ids.shape}, image is {frame.shape}"
        )
    if seg.n_segments == 0 or not (ids >= 0).any():
        raise ReconstructionInputError(f"{frame.name}: no segments in this image")
    if ids.max() >= seg.n_segments:
        raise ReconstructionInputError(
            f"{frame.name}: segment ids reach {ids.max()} but only {seg.n_segments} labels"
        )
    bad = sorted({lbl for lbl in seg.labels if lbl not in SEMANTIC_CLASSES})
    if bad:
        raise ReconstructionInputError(f"{frame.name}: unknown segment labels {bad}")
    return seg


def _complete_cut_doors(boxes, groups, door_ids, seg, level_from_cam, k, nominal_width_m):
    """Doors cut by the left/right image border are narrower than seen: widen each such box to
    ``nominal_width_m``, growing it towards the border (out of view), never shrinking it."""
    if not len(boxes) or nominal_width_m <= 0:
        return boxes
    boxes = boxes.copy()
    cam_from_level = np.linalg.inv(level_from_cam)
    for b, members in zip(boxes, groups, strict=True):
        if b[3] >= nominal_width_m:
            continue
        mask = np.isin(seg, [door_ids[m] for m in members])
        left, right = mask[:, :2].any(), mask[:, -2:].any()
        if not (left or right):
            continue
        a = np.array([np.cos(b[6]), np.sin(b[6]), 0.0])
        ends = np.stack([b[:3] - a * b[3] / 2, b[:3] + a * b[3] / 2])
        cam = ends @ cam_from_level[:3, :3].T + cam_from_level[:3, 3]
        u = k.fx * cam[:, 0] / np.maximum(cam[:, 2], 1e-6) + k.cx
        # the end nearest the border the mask touches is the one that continues out of view
        j = int(np.argmin(u)) if left and not right else int(np.argmax(u))
        grow = nominal_width_m - b[3]
        direction = -a if j == 0 else a
        b[:3] = b[:3] + direction * grow / 2
        b[3] = nominal_width_m
    return boxes


def estimate_depth(frame: FrameInput, config: ReconstructionConfig, backend) -> DepthResult:
    """Stage 1: metric depth of ``frame`` by ``backend``, checked (shape, at least one valid
    pixel) and clipped to ``config.max_depth_m`` (beyond it: 0, invalid)."""
    return _check_depth(frame, backend.estimate(frame), config.max_depth_m)


def segment_image(frame: FrameInput, depth: DepthResult, backend) -> Segments:
    """Stage 2: segments with semantic labels (and, for segmenters that measure them, gravity
    and doorway boxes), checked against the image and the vocabulary."""
    return _check_segments(frame, backend.segment(frame, depth))


def label_materials(frame: FrameInput, depth: DepthResult, segments: Segments,
                    config: ReconstructionConfig, backend) -> tuple[list[MaterialLabel], list[str]]:
    """Stage 3: one material label per segment; out-of-vocabulary answers become ``unknown``
    (marked ``fallback``, like the VLM's failed requests and unusable answers).

    Returns the labels and the fallbacks recorded on the way.
    """
    labels = list(backend.label(frame, depth, segments))
    if len(labels) != segments.n_segments:
        raise RuntimeError(
            f"{frame.name}: material backend {config.materials.name!r} returned {len(labels)} "
            f"labels for {segments.n_segments} segments"
        )
    fallbacks = []
    for i, lab in enumerate(labels):
        if lab.material not in MATERIAL_CLASSES:
            fallbacks.append(f"segment {i}: material {lab.material!r} not in vocabulary -> unknown")
            labels[i] = MaterialLabel("unknown", 0.0, f"out of vocabulary: {lab.material!r}",
                                      fallback=True)
    return labels, fallbacks


def build_scene(frame: FrameInput, depth: DepthResult, segments: Segments,
                labels: list[MaterialLabel], config: ReconstructionConfig, *,
                timings_s: dict[str, float] | None = None,
                fallbacks: list[str] | None = None) -> LabeledScene:
    """Stage 4: back-projection, gravity, one mesh per segment and door boxes.

    ``timings_s`` (the earlier stages' wall times) and ``fallbacks`` are carried into the
    scene; this stage adds ``backproject``, ``meshing`` and ``doors``.
    """
    if not config.rig_calibration:
        frame = frame.without_rig_calibration()
    timings = dict(timings_s or {})
    fallbacks = list(fallbacks or [])
    t = time.perf_counter()
    k = frame.intrinsics
    points = points_from_depth(depth.depth_m, k)
    step = max(1, round(k.width / 200))
    # the segmentation's gravity when it had one (its labels and door boxes are in that level
    # frame), else the rig's calibrated up, else normals + the image's vertical lines
    if segments.up_cam is not None:
        up = np.asarray(segments.up_cam, np.float64)
    else:
        up = gravity_up(normals_from_points(points, step_px=step), frame.rgb, k, frame.up_cam)
    level = level_from_camera(up)
    seg = segments.segment_id
    sem_lut = np.array([SEMANTIC_CLASSES.index(s) for s in segments.labels] + [0], np.uint8)
    mat_lut = np.array([MATERIAL_CLASSES.index(m.material) for m in labels] + [0], np.uint8)
    semantic_id = sem_lut[seg]  # -1 picks the trailing 0
    material_id = mat_lut[seg]
    timings["backproject"] = time.perf_counter() - t

    t = time.perf_counter()
    mesh_materials = []
    for i, lab in enumerate(labels):
        if lab.material == "unknown":
            fallbacks.append(f"segment {i} ({segments.labels[i]}): material unknown -> "
                             f"{config.unknown_material} for the radar mesh")
            mesh_materials.append(config.unknown_material)
        else:
            mesh_materials.append(lab.material)
    meshes = segment_meshes(points, seg, segments.labels, mesh_materials, k.fx,
                            config.meshing.to_config())
    timings["meshing"] = time.perf_counter() - t

    t = time.perf_counter()
    pl = points @ level[:3, :3].T.astype(np.float32)
    floor_pts = pl[semantic_id == SEMANTIC_CLASSES.index("floor")]
    floor_pts = floor_pts[np.isfinite(floor_pts).all(axis=1)]
    floor_z = float(np.median(floor_pts[:, 2])) if len(floor_pts) >= 20 else float("nan")
    door_ids = [i for i, s in enumerate(segments.labels) if s == "door"]
    wall_pts = pl[semantic_id == SEMANTIC_CLASSES.index("wall")]
    boxes, groups = fit_door_boxes([pl[seg == i] for i in door_ids], config.doors.to_config(),
                              None if np.isnan(floor_z) else floor_z, 1.0 / k.fx,
                              wall_pts[::max(1, len(wall_pts) // 20000)])
    boxes = _complete_cut_doors(boxes, groups, door_ids, seg, level, k,
                                config.doors.nominal_width_m)
    # doorways the segmentation measured on wall planes (door frames on the rectified wall,
    # openings seen through it) take precedence; a box fitted to door pixels is kept where no
    # measured one lies within 0.5 m or overlaps it along the wall
    measured = segments.door_boxes_level
    if len(measured):
        kept = [b for b in boxes
                if np.min(np.linalg.norm(measured[:, :2] - b[:2], axis=1)
                          - np.maximum(0.5, 0.5 * (measured[:, 3] + b[3]))) > 0]
        boxes = np.vstack([measured, *[b[None] for b in kept]]).astype(np.float32)
    boxes = dedupe_boxes(boxes)
    n_fitted = len(boxes)
    boxes = plausible_door_boxes(boxes, config.doors.to_config())  # doorway widths only
    door_pts = pl[semantic_id == SEMANTIC_CLASSES.index("door")]
    template = door_template_meshes(boxes, door_pts[np.isfinite(door_pts).all(axis=1)],
                                    None if np.isnan(floor_z) else floor_z,
                                    config.door_template.to_config())
    camera_from_level = np.linalg.inv(level)
    meshes = list(meshes) + [m.transformed(camera_from_level) for m in template]
    timings["doors"] = time.perf_counter() - t

    seg_info = dict(segments.info)
    if segments.up_cam is not None:
        seg_info["up_cam"] = segments.up_cam.tolist()
        seg_info["door_boxes_level"] = segments.door_boxes_level.tolist()
    info = {
        "depth": depth.info,
        "segments": seg_info,
        "up_cam": up.tolist(),
        "rig_calibration": frame.rig_calibration,
        "door_boxes_implausible": n_fitted - len(boxes),
        "fallbacks": fallbacks,
        "config": config.to_dict(),
    }
    for f in fallbacks:
        log.info("%s: %s", frame.name, f)
    return LabeledScene(
        name=frame.name, intrinsics=k, rgb=frame.rgb, depth_m=depth.depth_m, points_cam=points,
        segment_id=seg.astype(np.int32), segment_labels=tuple(segments.labels),
        segment_scores=np.asarray(segments.scores, np.float32),
        segment_materials=tuple(labels), semantic_id=semantic_id, material_id=material_id,
        meshes=meshes, door_boxes=boxes, level_from_camera=level, floor_z_m=floor_z,
        timings_s=timings, info=info,
    )


def reconstruct(
    frame: FrameInput,
    config: ReconstructionConfig | None = None,
    ground_truth=None,
    *,
    backends: tuple | None = None,
) -> LabeledScene:
    """Run the four stages on one frame (:func:`estimate_depth`, :func:`segment_image`,
    :func:`label_materials`, :func:`build_scene`; the capture factory runs them as separate,
    cached tasks).

    Parameters
    ----------
    frame : FrameInput — RGB, intrinsics, optional LiDAR (camera frame).
    config : ReconstructionConfig — backends and options (default: lidar/builtin/prior).
    ground_truth : ``WorldFrame``-like or dict — required by ``oracle`` backends.
    backends : (depth, segments, materials) instances — reuse across frames (e.g. a VLM
        client with its cache); default: built from ``config``.

    Returns
    -------
    LabeledScene

    Raises
    ------
    ReconstructionInputError
        Bad image/intrinsics/LiDAR, no valid depth, no segments.
    """
    config = config or ReconstructionConfig()
    timings: dict[str, float] = {}
    if not config.rig_calibration:
        frame = frame.without_rig_calibration()
    t0 = time.perf_counter()
    depth_be, seg_be, mat_be = backends or build_backends(config, ground_truth)

    t = time.perf_counter()
    depth = estimate_depth(frame, config, depth_be)
    timings["depth"] = time.perf_counter() - t

    t = time.perf_counter()
    segments = segment_image(frame, depth, seg_be)
    timings["segments"] = time.perf_counter() - t

    t = time.perf_counter()
    labels, fallbacks = label_materials(frame, depth, segments, config, mat_be)
    timings["materials"] = time.perf_counter() - t

    scene = build_scene(frame, depth, segments, labels, config, timings_s=timings,
                        fallbacks=fallbacks)
    scene.timings_s["total"] = time.perf_counter() - t0
    return scene
