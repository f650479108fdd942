"""Declared Parquet schemas, one per artifact stage — the single place a table layout is defined.

Every artifact the store writes or reads is validated against the :class:`ArtifactSchema`
registered for its stage. Arrays are typed Arrow list columns (``list<float32>``,
``list<fixed_size_list<float32, 3>>``, ...) or ``binary`` (e.g. PNG bytes) — never pickles.
Units live in the field names and in each field's metadata (``unit``, ``doc``).

Adding a stage (other helpers / stages): append a clearly delimited block at the end of this
file that calls :func:`register_schema`, e.g.::

    # ---- worlds (owner: worlds stage) ------------------------------------------------------
    WORLD_FRAMES = register_schema(ArtifactSchema(
        stage="world_frames", version=1, row="one rendered frame",
        description="RGB/depth/masks of a procedural world",
        schema=pa.schema([field("frame_index", pa.int32(), doc="frame number"), ...]),
    ))

Bump ``version`` (and the producing stage's ``stage_version``) whenever the layout changes; a
file whose recorded schema version differs from the declared one is refused with a clear error.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import pyarrow as pa

__all__ = [
    "ArtifactSchema",
    "SchemaError",
    "field",
    "register_schema",
    "get_schema",
    "schema_names",
    "SCENE_MESHES",
    "RADAR_POINTS",
    "MANIFEST",
]


class SchemaError(ValueError):
    """A table does not match its declared schema; the message names the stage and column."""


def field(name: str, type_: pa.DataType, *, unit: str = "", doc: str = "", nullable: bool = False):
    """A ``pa.field`` carrying ``unit`` and ``doc`` metadata (shown by ``describe()``)."""
    meta = {}
    if unit:
        meta["unit"] = unit
    if doc:
        meta["doc"] = doc
    return pa.field(name, type_, nullable=nullable, metadata=meta or None)


@dataclasses.dataclass(frozen=True)
class ArtifactSchema:
    """The declared layout of one stage's artifacts.

    Attributes
    ----------
    stage : str
        Stage name (store folder), lowercase snake case.
    version : int
        Layout version, recorded in every file's metadata and checked on read.
    schema : pyarrow.Schema
        Column names, types, nullability; field metadata gives ``unit`` and ``doc``.
    row : str
        What one row is (``"one radar frame"``).
    description : str
        One line on the artifact.
    """

    stage: str
    version: int
    schema: pa.Schema
    row: str
    description: str

    def validate(self, table: pa.Table) -> pa.Table:
        """Return ``table`` with columns in declared order and types, or raise :class:`SchemaError`.

        Missing or unexpected columns, nulls in non-nullable columns, and values that do not
        fit a declared type (e.g. ``float64`` that would lose data as ``int32``) are refused.
        Lossless conversions (``int64`` -> ``int32`` within range, ``list<float64>`` ->
        ``list<float32>``) are applied.
        """
        where = f"stage {self.stage!r} (schema v{self.version})"
        if not isinstance(table, pa.Table):
            raise SchemaError(f"{where}: expected a pyarrow.Table, got {type(table).__name__}")
        declared = self.schema.names
        missing = [n for n in declared if n not in table.column_names]
        extra = [n for n in table.column_names if n not in declared]
        if missing or extra:
            raise SchemaError(
                f"{where}: columns do not match the declared schema in storage/schemas.py; "
                f"missing {missing}, unexpected {extra}; declared columns: {declared}"
            )
        columns = []
        for f in self.schema:
            col = table.column(f.name)
            if not col.type.equals(f.type):
                if not _same_kind(col.type, f.type):
                    raise SchemaError(
                        f"{where}: column {f.name!r} has type {col.type}, declared {f.type}"
                    )
                try:
                    # float64 -> float32 is a declared narrowing for array payloads; everything
                    # else must be safe (no overflow, no truncation)
                    col = col.cast(f.type, safe=not _is_float_narrowing(col.type, f.type))
                except (pa.ArrowInvalid, pa.ArrowNotImplementedError) as exc:
                    raise SchemaError(
                        f"{where}: column {f.name!r} has type {col.type}, declared {f.type}; "
                        f"cannot convert: {exc}"
                    ) from None
            if not f.nullable and col.null_count:
                raise SchemaError(
                    f"{where}: column {f.name!r} has {col.null_count} null value(s) but is "
                    "declared non-nullable"
                )
            columns.append(col)
        return pa.Table.from_arrays(columns, schema=self.schema)

    def check_file_schema(self, file_schema: pa.Schema, where: str) -> None:
        """Refuse a stored file whose columns/types differ from the declared schema."""
        got = {f.name: f.type for f in file_schema}
        want = {f.name: f.type for f in self.schema}
        if got != want:
            diff = sorted(
                n for n in set(got) | set(want) if got.get(n) is None or not got[n].equals(want.get(n))
            )
            raise SchemaError(
                f"{where}: stored columns differ from stage {self.stage!r} schema v{self.version} "
                f"in {diff}; the file was written by another version of the code — bump the "
                "stage version to recompute it, or read it with the matching code version"
            )

    def describe(self) -> str:
        """Human-readable column list with units."""
        lines = [f"{self.stage} v{self.version} — {self.description} (one row = {self.row})"]
        for f in self.schema:
            meta = {k.decode(): v.decode() for k, v in (f.metadata or {}).items()}
            unit = f" [{meta['unit']}]" if meta.get("unit") else ""
            doc = f" — {meta['doc']}" if meta.get("doc") else ""
            lines.append(f"  {f.name}: {f.type}{unit}{doc}")
        return "\n".join(lines)


def _kind(t: pa.DataType) -> str:
    if pa.types.is_integer(t) or pa.types.is_floating(t):
        return "number"
    if pa.types.is_string(t) or pa.types.is_large_string(t):
        return "string"
    if pa.types.is_binary(t) or pa.types.is_large_binary(t) or pa.types.is_fixed_size_binary(t):
        return "binary"
    if pa.types.is_list(t) or pa.types.is_large_list(t) or pa.types.is_fixed_size_list(t):
        return "list"
    return str(t)


def _same_kind(src: pa.DataType, dst: pa.DataType) -> bool:
    """True if converting ``src`` to ``dst`` keeps meaning (number->number, list->list, ...);
    numbers never silently become strings and vice versa."""
    if _kind(src) != _kind(dst):
        return pa.types.is_timestamp(src) and pa.types.is_timestamp(dst)
    if _kind(src) == "list":
        return _same_kind(src.value_type, dst.value_type)
    if pa.types.is_integer(dst) and pa.types.is_floating(src):
        return False  # float -> int would truncate
    return True


def _is_float_narrowing(src: pa.DataType, dst: pa.DataType) -> bool:
    """True if ``src`` -> ``dst`` only narrows floating point values (possibly inside lists)."""
    while pa.types.is_list(src) or pa.types.is_large_list(src) or pa.types.is_fixed_size_list(src):
        if not (pa.types.is_list(dst) or pa.types.is_large_list(dst) or pa.types.is_fixed_size_list(dst)):
            return False
        src, dst = src.value_type, dst.value_type
    return pa.types.is_floating(src) and pa.types.is_floating(dst)


_REGISTRY: dict[str, ArtifactSchema] = {}


def register_schema(schema: ArtifactSchema) -> ArtifactSchema:
    """Declare a stage's schema. Re-registering the identical schema is a no-op; a different
    one under the same stage name is an error (two stages must not share a folder)."""
    old = _REGISTRY.get(schema.stage)
    if old is not None and (old.version != schema.version or not old.schema.equals(schema.schema)):
        raise ValueError(f"stage {schema.stage!r} already has a different declared schema")
    _REGISTRY[schema.stage] = schema
    return schema


def get_schema(stage: str) -> ArtifactSchema:
    """The declared schema of ``stage``; an unknown name lists the declared ones."""
    try:
        return _REGISTRY[stage]
    except KeyError:
        raise SchemaError(
            f"no schema declared for stage {stage!r}; declared stages: {schema_names()}. "
            "Declare it with register_schema(...) in storage/schemas.py"
        ) from None


def schema_names() -> list[str]:
    """Declared stage names, sorted."""
    return sorted(_REGISTRY)


def iter_schemas() -> Iterator[ArtifactSchema]:
    """All declared schemas, sorted by stage."""
    return (_REGISTRY[n] for n in schema_names())


# ---------------------------------------------------------------------------------------------
# Core stages (owner: storage / radar simulation)
# ---------------------------------------------------------------------------------------------
_VEC3_F32 = pa.list_(pa.float32(), 3)
_TRI_I32 = pa.list_(pa.int32(), 3)
_BOX7_F32 = pa.list_(pa.float32(), 7)
_MAT44_F64 = pa.list_(pa.float64(), 16)

SCENE_MESHES = register_schema(
    ArtifactSchema(
        stage="scene_meshes",
        version=1,
        row="one material-labelled triangle mesh",
        description="a scene as MaterialMesh list (world frame), input of the radar simulation",
        schema=pa.schema(
            [
                field("name", pa.string(), doc="mesh name, unique within the scene"),
                field("material", pa.string(), doc="material name understood by sim2radar.em"),
                field("semantic", pa.string(), doc="class label (vocab.SEMANTIC_CLASSES) or ''"),
                field("vertices_m", pa.list_(_VEC3_F32), unit="m", doc="(V, 3) vertex positions"),
                field("faces", pa.list_(_TRI_I32), doc="(F, 3) vertex indices per triangle"),
            ]
        ),
    )
)

RADAR_POINTS = register_schema(
    ArtifactSchema(
        stage="radar_points",
        version=1,
        row="one simulated radar frame",
        description="radar point cloud per frame (radar frame: x forward, y left, z up) + door boxes",
        schema=pa.schema(
            [
                field("scene_id", pa.string(), doc="scene name"),
                field("frame_index", pa.int32(), doc="frame number within the scene"),
                field(
                    "radar_to_world",
                    _MAT44_F64,
                    unit="m",
                    doc="(4, 4) row-major radar-to-world transform (translation in m)",
                ),
                field("n_points", pa.int32(), doc="number of detected points"),
                field("x_m", pa.list_(pa.float32()), unit="m", doc="(N,) forward coordinate"),
                field("y_m", pa.list_(pa.float32()), unit="m", doc="(N,) left coordinate"),
                field("z_m", pa.list_(pa.float32()), unit="m", doc="(N,) up coordinate"),
                field("intensity_db", pa.list_(pa.float32()), unit="dB", doc="(N,) intensity"),
                field(
                    "boxes",
                    pa.list_(_BOX7_F32),
                    unit="m, rad",
                    doc="(M, 7) ground-truth boxes x y z dx dy dz heading in the radar frame",
                ),
                field("box_labels", pa.list_(pa.string()), doc="(M,) class name of each box"),
                field("sim_seconds", pa.float64(), unit="s", doc="simulation wall time"),
            ]
        ),
    )
)

MANIFEST = register_schema(
    ArtifactSchema(
        stage="manifest",
        version=2,
        row="one scene of a dataset",
        description="per-dataset run record: status, error, artifact keys, timings, fallbacks",
        schema=pa.schema(
            [
                field("scene_id", pa.string(), doc="scene identifier within the dataset"),
                field("status", pa.string(), doc="ok (computed) | skipped (cached) | failed"),
                field("error", pa.string(), doc="error text when failed, else ''"),
                field(
                    "artifacts",
                    pa.map_(pa.string(), pa.string()),
                    doc="stage -> content key of each artifact of this scene",
                ),
                field("timings_s", pa.map_(pa.string(), pa.float64()), unit="s", doc="per step"),
                field("source", pa.string(), doc="where the scene came from (file path / URI)"),
                field("attempts", pa.int32(), doc="how many runs have processed this scene"),
                field("updated_utc", pa.timestamp("ms", tz="UTC"), doc="last update"),
                field("fallbacks", pa.int32(),
                      doc="segments whose material fell back to unknown in the geometry this "
                          "row was made from (its artifacts are provisional: the next run "
                          "computes them again); 0 for v1 rows"),
            ]
        ),
    )
)

# ---------------------------------------------------------------------------------------------
# Further stages: append blocks below (see module docstring).
# ---------------------------------------------------------------------------------------------

# ---------------------------------------------------------------------------------------------
# worlds (owner: procedural worlds stage, sim2radar/worlds + tasks/worlds.py)
# World geometry itself is stored as a ``scene_meshes`` artifact (radar-ready).
# ---------------------------------------------------------------------------------------------
_VEC2_F64 = pa.list_(pa.float64(), 2)

WORLD_SPECS = register_schema(
    ArtifactSchema(
        stage="world_specs",
        version=1,
        row="one procedural world",
        description="layout, object table (semantic/material/appearance) and door boxes of a world",
        schema=pa.schema(
            [
                field("world_id", pa.string(), doc="world identifier (world_<seed>)"),
                field("seed", pa.int64(), doc="world seed"),
                field("layout", pa.string(), doc="straight | t_junction | l_turn"),
                field("ceiling_height_m", pa.float64(), unit="m", doc="ceiling height"),
                field("spaces_json", pa.string(), doc="JSON list of corridors/rooms (rect_m x0 x1 y0 y1)"),
                field("doors_json", pa.string(), doc="JSON list of doors (kind, state, swing_deg, ...)"),
                field(
                    "door_boxes_world",
                    pa.list_(_BOX7_F32),
                    unit="m, rad",
                    doc="(M, 7) door boxes x y z dx dy dz heading, world frame",
                ),
                field("object_names", pa.list_(pa.string()), doc="(O,) object/mesh names"),
                field("object_semantics", pa.list_(pa.string()), doc="(O,) vocab.SEMANTIC_CLASSES"),
                field("object_materials", pa.list_(pa.string()), doc="(O,) vocab.MATERIAL_CLASSES"),
                field("object_kinds", pa.list_(pa.string()), doc="(O,) door_leaf, cabinet, ..."),
                field("object_door_index", pa.list_(pa.int32()), doc="(O,) door index or -1"),
                field("object_space_index", pa.list_(pa.int32()), doc="(O,) space index or -1"),
                field("appearances_json", pa.string(), doc="JSON list of (O,) optical appearances"),
                field("path_world_m", pa.list_(_VEC2_F64), unit="m", doc="(P, 2) corridor centre-line"),
                field("config_json", pa.string(), doc="resolved WorldConfig as JSON"),
            ]
        ),
    )
)

WORLD_FRAMES = register_schema(
    ArtifactSchema(
        stage="world_frames",
        version=1,
        row="one rendered frame of a world",
        description="RGB (PNG), depth (float16), normals, instance/semantic/material masks (PNG), "
        "LiDAR, poses, intrinsics, door boxes with flags",
        schema=pa.schema(
            [
                field("world_id", pa.string(), doc="world identifier"),
                field("seed", pa.int64(), doc="world seed"),
                field("frame_index", pa.int32(), doc="frame number along the trajectory"),
                field("width", pa.int32(), unit="px", doc="image width"),
                field("height", pa.int32(), unit="px", doc="image height"),
                field("fx", pa.float64(), unit="px", doc="focal length x"),
                field("fy", pa.float64(), unit="px", doc="focal length y"),
                field("cx", pa.float64(), unit="px", doc="principal point x"),
                field("cy", pa.float64(), unit="px", doc="principal point y"),
                field("rgb_png", pa.binary(), doc="sRGB image, 8-bit PNG"),
                field(
                    "depth_f16",
                    pa.binary(),
                    unit="m",
                    doc="(H, W) z-depth, little-endian float16 row-major, 0 = no surface",
                ),
                field("depth_min_m", pa.float32(), unit="m", doc="smallest valid depth"),
                field("depth_max_m", pa.float32(), unit="m", doc="largest depth"),
                field("normals_png", pa.binary(), doc="camera-frame normals, PNG of (n + 1) * 127.5"),
                field("instance_png", pa.binary(), doc="16-bit PNG of instance_id + 1 (0 = none)"),
                field("semantic_png", pa.binary(), doc="8-bit PNG of vocab.SEMANTIC_CLASSES ids"),
                field("material_png", pa.binary(), doc="8-bit PNG of vocab.MATERIAL_CLASSES ids"),
                field(
                    "lidar_points_cam_m",
                    pa.list_(_VEC3_F32),
                    unit="m",
                    doc="(N, 3) LiDAR returns in the camera frame (OpenCV axes)",
                ),
                field("lidar_ring", pa.list_(pa.uint8()), doc="(N,) beam index per return"),
                field("camera_to_world", _MAT44_F64, unit="m", doc="(4, 4) row-major"),
                field("radar_to_world", _MAT44_F64, unit="m", doc="(4, 4) row-major"),
                field("lidar_to_world", _MAT44_F64, unit="m", doc="(4, 4) row-major"),
                field("rig_to_world", _MAT44_F64, unit="m", doc="(4, 4) row-major"),
                field("lidar_to_camera", _MAT44_F64, unit="m", doc="(4, 4) row-major"),
                field("door_boxes_world", pa.list_(_BOX7_F32), unit="m, rad", doc="(M, 7) world"),
                field("door_boxes_radar", pa.list_(_BOX7_F32), unit="m, rad", doc="(M, 7) radar"),
                field("door_visible", pa.list_(pa.bool_()), doc="(M,) seen by the camera"),
                field("door_visible_pixels", pa.list_(pa.int32()), unit="px", doc="(M,) pixels"),
                field("door_in_fov", pa.list_(pa.bool_()), doc="(M,) centre in radar FOV"),
                field("door_in_range", pa.list_(pa.bool_()), doc="(M,) centre within max range"),
                field("render_seconds", pa.float64(), unit="s", doc="render wall time"),
            ]
        ),
    )
)
# ---- end worlds ------------------------------------------------------------------------------


# --- reconstruction (sim2radar.reconstruct; written by storage/reconstruction.py) ---------
RECONSTRUCTION = register_schema(
    ArtifactSchema(
        stage="reconstruction",
        version=1,
        row="one reconstructed RGB frame",
        description="per-pixel depth/segments/semantics/materials, segment labels, door boxes",
        schema=pa.schema([
            field("name", pa.string(), doc="frame name"),
            field("width", pa.int32(), unit="px"),
            field("height", pa.int32(), unit="px"),
            field("intrinsics", pa.list_(pa.float64(), 4), unit="px", doc="fx, fy, cx, cy"),
            field("depth_m", pa.list_(pa.float32()), unit="m", doc="(H*W,) z-depth, 0 invalid"),
            field("segment_id", pa.list_(pa.int32()), doc="(H*W,) segment per pixel, -1 none"),
            field("semantic_id", pa.list_(pa.uint8()), doc="(H*W,) vocab.SEMANTIC_CLASSES index"),
            field("material_id", pa.list_(pa.uint8()), doc="(H*W,) vocab.MATERIAL_CLASSES index"),
            field("segment_labels", pa.list_(pa.string()), doc="(S,) semantic class"),
            field("segment_scores", pa.list_(pa.float32()), doc="(S,) label confidence"),
            field("segment_materials", pa.list_(pa.string()), doc="(S,) material class"),
            field("material_confidence", pa.list_(pa.float32()), doc="(S,) in [0, 1]"),
            field("material_reasons", pa.list_(pa.string()), doc="(S,) rule / VLM reasoning"),
            field("door_boxes", pa.list_(_BOX7_F32), unit="m, rad",
                  doc="(M, 7) x y z dx dy dz heading in the artifact's target frame"),
            field("camera_to_target", pa.list_(pa.float64(), 16),
                  doc="(4, 4) row-major camera -> target frame of meshes and boxes"),
            field("level_from_camera", pa.list_(pa.float64(), 16),
                  doc="(4, 4) row-major camera -> level frame (x fwd, y left, z up)"),
            field("floor_z_m", pa.float64(), unit="m", doc="floor height, level frame"),
            field("timings_s", pa.map_(pa.string(), pa.float64()), unit="s", doc="per stage"),
            field("info_json", pa.string(), doc="backend diagnostics and fallbacks (JSON)"),
        ]),
    )
)


# --- dataset_frames (the factory's flows: tasks/dataset.py, tasks/reference.py) -------------
DATASET_FRAMES = register_schema(
    ArtifactSchema(
        stage="dataset_frames",
        version=3,
        row="one radar frame of one world frame and one geometry",
        description="radar points (radar frame) + door labels with their visibility + "
        "ground-truth doors + timings",
        schema=pa.schema([
            field("frame_id", pa.string(), doc="world_<seed>_f<index>"),
            field("world_id", pa.string(), doc="world identifier (world_<seed>)"),
            field("seed", pa.int64(), doc="world seed"),
            field("frame_index", pa.int32(), doc="frame number along the world's trajectory"),
            field("geometry", pa.string(), doc="ground_truth | reconstructed"),
            field("radar_fidelity", pa.string(), doc="raytrace | signal (RadarConfig.fidelity)"),
            field("radar_to_world", pa.list_(pa.float64(), 16), unit="m",
                  doc="(4, 4) row-major radar-to-world transform"),
            field("n_points", pa.int32(), doc="detected radar points"),
            field("x_m", pa.list_(pa.float32()), unit="m", doc="(N,) forward"),
            field("y_m", pa.list_(pa.float32()), unit="m", doc="(N,) left"),
            field("z_m", pa.list_(pa.float32()), unit="m", doc="(N,) up"),
            field("intensity_db", pa.list_(pa.float32()), unit="dB", doc="(N,) intensity"),
            field("doppler_mps", pa.list_(pa.float32()), unit="m/s",
                  doc="(N,) radial velocity (0 for the ray tracer)"),
            field("boxes", pa.list_(_BOX7_F32), unit="m, rad",
                  doc="(M, 7) training labels x y z dx dy dz heading, radar frame"),
            field("box_labels", pa.list_(pa.string()), doc="(M,) class names"),
            field("label_visibility", pa.list_(pa.float32()),
                  doc="(M,) fraction of each label's doorway the radar sees"),
            field("gt_boxes", pa.list_(_BOX7_F32), unit="m, rad",
                  doc="(G, 7) ground-truth doors the radar sees, radar frame"),
            field("gt_door_index", pa.list_(pa.int32()), doc="(G,) index into the world's doors"),
            field("gt_points_near", pa.list_(pa.int32()),
                  doc="(G,) radar points inside each GT box grown by NEAR_BOX_MARGIN_M"),
            field("gt_visibility", pa.list_(pa.float32()),
                  doc="(G,) fraction of each ground-truth doorway the radar sees"),
            field("n_triangles", pa.int64(), doc="triangles the radar traced"),
            field("timings_s", pa.map_(pa.string(), pa.float64()), unit="s",
                  doc="render / reconstruct / simulate wall time of this frame"),
            field("stats_json", pa.string(), doc="radar stats, reconstruction diagnostics (JSON)"),
            field("surface_offset_m", pa.list_(pa.float32()), unit="m",
                  doc="(N,) point range minus the first world surface along its ray (inf: "
                  "none; NaN: geometry unknown)"),
        ]),
    )
)


# --- experiment_runs (the experiment sweep; sim2radar/experiment + tasks/experiment.py) ------
# The row is declared once, in the library (sim2radar.experiment.rows.RUN_COLUMNS); the
# dashboard's check of runs.parquet derives from the same declaration.
def _declared_fields(columns) -> list[pa.Field]:
    """Parquet fields of a row declared in the library (:class:`sim2radar.experiment.rows.
    Column`: name, type, unit, doc, nullable)."""
    return [field(c.name, c.arrow_type(), unit=c.unit, doc=c.doc, nullable=c.nullable)
            for c in columns]


def _run_columns():
    from sim2radar.experiment.rows import RUN_COLUMNS

    return RUN_COLUMNS


EXPERIMENT_RUNS = register_schema(
    ArtifactSchema(
        stage="experiment_runs",
        version=1,
        row="one fine-tuning run of the experiment grid (condition x fraction x trial)",
        description="test-split AP, learning curves, timing and outcome of one training run",
        schema=pa.schema(_declared_fields(_run_columns())),
    )
)


# --- experiment_pretrain (every pre-training of a sweep, checked; tasks/experiment.py) ------
_CHECK_FIELDS = [
    field(f"{where}_ap_{metric}_r40_iou03", pa.float64(), unit="%", nullable=True,
          doc=f"{metric.upper()} AP, R40, IoU 0.3 of the pre-trained detector (encoder and head, "
              f"no fine-tuning) {text} (null: no such frames)")
    for where, text in (("train", "on its own (simulated) training frames"),
                        ("heldout", "on the held-out simulated split (worlds it never saw)"),
                        ("zero_shot", "zero-shot on the real validation split"))
    for metric in ("3d", "bev")
]

EXPERIMENT_PRETRAININGS = register_schema(
    ArtifactSchema(
        stage="experiment_pretrain",
        version=1,
        row="one pre-training of the experiment sweep, with its learnability check",
        description="what a pre-training learned before any fine-tuning (held-out sim AP, "
                    "zero-shot real AP), its loss curve, timing and outcome",
        schema=pa.schema([
            field("sweep", pa.string(), doc="sweep name"),
            field("pretrain_key", pa.string(), doc="content key of the pre-training"),
            field("pretrain_id", pa.string(), doc="readable id, e.g. pretrain-sim-t2-f0.05"),
            field("sim_role", pa.string(), doc="dataset role it trained on (sim, sim-gt, ref...)"),
            field("conditions", pa.list_(pa.string()),
                  doc="conditions whose runs load its encoder"),
            field("trial", pa.int32(), nullable=True, doc="trial index (null: shared)"),
            field("fraction", pa.float64(), nullable=True,
                  doc="real fraction whose intensities it was matched to (null: none)"),
            field("seed", pa.int64(), doc="seed of its weights and data order"),
            field("n_sim_frames", pa.int32(), doc="simulated frames it trained on"),
            field("holdout_split", pa.string(), nullable=True,
                  doc="sim split held out of it (null: trained on every frame)"),
            field("n_heldout_frames", pa.int32(), doc="held-out sim frames checked"),
            field("n_real_val_frames", pa.int32(), doc="real validation frames checked"),
            *_CHECK_FIELDS,
            field("epochs", pa.int32(), doc="pre-training epochs"),
            field("steps", pa.int32(), doc="optimiser steps"),
            field("history_epoch", pa.list_(pa.int32()), doc="(E,) epoch numbers"),
            field("history_loss", pa.list_(pa.float64()), doc="(E,) mean training loss"),
            field("wall_time_s", pa.float64(), unit="s", doc="training wall time"),
            field("check_s", pa.float64(), unit="s", doc="wall time of the check"),
            field("checkpoint", pa.string(), doc="its checkpoint, relative to the sweeps folder"),
            field("status", pa.string(), doc="ok | failed | skipped"),
            field("error", pa.string(), doc="failure reason, empty when ok"),
            field("finished_at", pa.string(), doc="UTC ISO-8601 time it finished"),
        ]),
    )
)


# --- reconstruction stages one by one (the capture factory: tasks/capture.py) ---------------
# Each stage of sim2radar.reconstruct.pipeline is its own cached artifact, so a run that
# changes only the material backend re-labels materials without re-estimating depth.
DEPTH_MAPS = register_schema(
    ArtifactSchema(
        stage="depth_maps",
        version=1,
        row="stage 1 of one RGB frame: metric depth",
        description="(H, W) z-depth of a frame from the depth backend, with its diagnostics",
        schema=pa.schema([
            field("name", pa.string(), doc="frame / scene name"),
            field("width", pa.int32(), unit="px"),
            field("height", pa.int32(), unit="px"),
            field("depth_m", pa.list_(pa.float32()), unit="m", doc="(H*W,) z-depth, 0 invalid"),
            field("info_json", pa.string(), doc="depth backend diagnostics (JSON)"),
            field("seconds", pa.float64(), unit="s", doc="stage wall time"),
        ]),
    )
)

SEGMENTATIONS = register_schema(
    ArtifactSchema(
        stage="segmentations",
        version=1,
        row="stage 2 of one RGB frame: segments with semantic labels",
        description="segment per pixel, semantic class and score per segment, the "
        "segmenter's gravity and measured doorway boxes",
        schema=pa.schema([
            field("name", pa.string(), doc="frame / scene name"),
            field("width", pa.int32(), unit="px"),
            field("height", pa.int32(), unit="px"),
            field("segment_id", pa.list_(pa.int32()), doc="(H*W,) segment per pixel, -1 none"),
            field("labels", pa.list_(pa.string()), doc="(S,) vocab.SEMANTIC_CLASSES"),
            field("scores", pa.list_(pa.float32()), doc="(S,) label confidence in [0, 1]"),
            field("up_cam", pa.list_(pa.float64()), nullable=True,
                  doc="(3,) gravity up in the camera frame, or null (none measured)"),
            field("door_boxes_level", pa.list_(_BOX7_F32), unit="m, rad",
                  doc="(M, 7) doorways measured by the segmenter, level frame of up_cam"),
            field("info_json", pa.string(), doc="segmenter diagnostics (JSON)"),
            field("seconds", pa.float64(), unit="s", doc="stage wall time"),
        ]),
    )
)

MATERIAL_LABELS = register_schema(
    ArtifactSchema(
        stage="material_labels",
        version=1,
        row="stage 3 of one RGB frame: a material per segment",
        description="material class, confidence and reason (rule or VLM reasoning) per segment",
        schema=pa.schema([
            field("name", pa.string(), doc="frame / scene name"),
            field("materials", pa.list_(pa.string()), doc="(S,) vocab.MATERIAL_CLASSES"),
            field("confidence", pa.list_(pa.float32()), doc="(S,) in [0, 1]"),
            field("reasons", pa.list_(pa.string()), doc="(S,) why"),
            field("fallbacks", pa.list_(pa.string()), doc="fallbacks recorded by the stage"),
            field("seconds", pa.float64(), unit="s", doc="stage wall time"),
        ]),
    )
)
