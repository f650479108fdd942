"""The run specification of the procedural-world factory: :class:`DatasetSpec` (frames per world,
geometries, radar, reconstruction, world, rig, seed, label rule, ...), a pydantic model that
validates and resolves itself and travels whole from the command line to the flow, its tasks
and deployments; and what an export says about itself (:func:`dataset_metadata`). Pure
configuration: no store, no Prefect."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    WithJsonSchema,
    model_serializer,
    model_validator,
)

from sim2radar.configio import (
    DEFAULT_RADAR,
    bundled_configs,
    config_path,
    load_yaml,
    looks_like_path,
    short_text,
    whole_number,
)
from sim2radar.factory.labels import (
    DEFAULT_POINT_CLOUD_RANGE_M,
    ClassName,
    LabelConfig,
    boxes_in_point_cloud_range,
)
from sim2radar.radar.config import RadarConfig
from sim2radar.reconstruct.pipeline import ReconstructionConfig
from sim2radar.worlds.config import RigConfig, RigMotion, WorldConfig

__all__ = ["GEOMETRIES", "DEFAULT_RADAR", "DatasetSpec", "resolve_radar",
           "resolve_reconstruction", "dataset_metadata",
           "GENERATE_CONFIG_KEYS", "load_generate_config", "label_range",
           "MAX_FRAMES_PER_WORLD", "MAX_WORLDS"]

def _named_or_fields(what: str) -> WithJsonSchema:
    """The JSON schema of a config field's *input* form (a deployment's parameter schema,
    which Prefect's server enforces): a name or path, or the config's fields."""
    return WithJsonSchema({"anyOf": [{"type": "string"}, {"type": "object"}, {"type": "null"}],
                           "description": f"{what}: a preset name, a YAML path or its fields"})


#: A config field: typed as the resolved config, given as a name, a path or fields.
RadarSetting = Annotated[RadarConfig, _named_or_fields("radar")]
ReconstructionSetting = Annotated[ReconstructionConfig, _named_or_fields("reconstruction")]
WorldSetting = Annotated[WorldConfig, _named_or_fields("world")]
RigSetting = Annotated[RigConfig, _named_or_fields("rig")]
MotionSetting = Annotated[RigMotion | None, _named_or_fields("motion")]

#: Geometry modes: radar simulated on the world's meshes, or on meshes reconstructed from RGB.
GEOMETRIES = ("ground_truth", "reconstructed")


#: The most frames along one world's trajectory (a world's rendered frames are held in memory
#: together: ~3 MB each at 640 x 480) and the most worlds one run takes (one task and one
#: manifest row each): bounds checked before any work.
MAX_FRAMES_PER_WORLD = 1000
MAX_WORLDS = 100_000


class DatasetSpec(BaseModel):
    """Resolved configuration of a dataset run (everything but the world seeds and the store).

    Built from settings (``DatasetSpec.model_validate({"radar": "ti-mmwcas", "geometry":
    "both", ...})``, or keyword arguments): names, paths and dicts are resolved into configs and
    every field is checked here, so a bad one fails before any work, named. The resolved spec
    is what the CLI hands the flow, the flow its tasks and a deployment takes as one parameter;
    its JSON form (:meth:`to_dict`) validates back into the same spec.

    Attributes
    ----------
    frames_per_world : int — frames along each world's trajectory.
    geometries : tuple[str, ...] — subset of :data:`GEOMETRIES` (input key ``geometry`` also
        takes ``"both"`` or one mode).
    radar : RadarConfig — from a preset name, YAML path or fields (:func:`resolve_radar`).
    reconstruction : ReconstructionConfig — from a preset name, YAML path, fields or None (the
        built-in backends with LiDAR: lidar / builtin / prior).
    world : WorldConfig
    rig : RigConfig — its radar FOV/range (for the door flags) match ``radar``.
    seed : int — run seed: trajectories and radar noise derive from it.
    class_name : str — label class of door boxes (the detector's ``class_names``).
    labels : LabelConfig — a door is a label when the radar sees enough of its doorway.
    material_override : str or None — simulate every mesh as this material (the
        "one material" ablation: what the material step contributes); None keeps each mesh's.
    export_label_range_m : (6,) or None — OpenPCDet exports keep only labels whose centre lies
        in this point-cloud range [m] (``"detector"``: the detector's; None keeps every label).
    render_rgb : bool — path trace RGB and cast LiDAR for the world frames (needed by
        ``reconstructed``; a ground-truth-only run such as the reference radar can skip it).
    motion : RigMotion or None — the rig's speed range while frames are taken (Doppler of the
        signal-level radar; the ray tracer's Doppler bins; :func:`sim2radar.worlds.trajectory.
        rig_velocity`); by default a person walking (:data:`sim2radar.worlds.config.
        WALKING_SPEED_MPS`, drawn per frame); None or ``{speed_mps: [0, 0]}``: standing still.
    """

    # the JSON schema (a deployment's parameter schema, which Prefect's server enforces) is
    # the input form: `geometry` may be one mode, "both" or a list; `export_label_range_m`
    # "detector"; the configs names, paths or fields
    model_config = ConfigDict(frozen=True, extra="forbid", populate_by_name=True,
                              validate_default=True)

    frames_per_world: int = Field(4, ge=1, le=MAX_FRAMES_PER_WORLD)
    geometries: tuple[str, ...] | str = Field(("reconstructed",), alias="geometry")
    radar: RadarSetting = DEFAULT_RADAR
    reconstruction: ReconstructionSetting = None
    world: WorldSetting = None
    rig: RigSetting = None
    seed: int = 0
    class_name: ClassName = "door"
    labels: LabelConfig = LabelConfig()
    material_override: str | None = None
    export_label_range_m: tuple[float, ...] | str | None = DEFAULT_POINT_CLOUD_RANGE_M
    render_rgb: bool = True
    motion: MotionSetting = None

    @model_validator(mode="before")
    @classmethod
    def _resolve(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        from sim2radar.worlds.config import WALKING_SPEED_MPS, RigMotion, resolve_world_configs

        data = dict(data)
        geometry = data.pop("geometry", data.pop("geometries", "reconstructed"))
        data["geometry"] = _geometries(geometry)
        data["radar"] = radar = resolve_radar(data.get("radar", DEFAULT_RADAR))
        data["reconstruction"] = resolve_reconstruction(data.get("reconstruction"))
        world, rig = resolve_world_configs(data.get("world"), data.get("rig"))
        data["world"], data["rig"] = world, _rig_for_radar(rig, radar)
        if data.get("material_override") is not None:
            from sim2radar.em import get_material

            try:
                data["material_override"] = get_material(data["material_override"]).name
            except KeyError as exc:
                raise ValueError(f"material_override: {exc}") from None
        if data.get("labels") is None:
            data.pop("labels", None)
        rng = label_range(data.get("export_label_range_m", DEFAULT_POINT_CLOUD_RANGE_M))
        if rng is not None:
            boxes_in_point_cloud_range(np.zeros((0, 7)), rng)  # validates
            rng = tuple(float(v) for v in rng)
        data["export_label_range_m"] = rng
        # a walking rig unless told otherwise (None or speed 0 0: at rest)
        motion = data.get("motion", {"speed_mps": list(WALKING_SPEED_MPS)})
        if motion is not None and not isinstance(motion, RigMotion):
            try:
                motion = RigMotion.model_validate(motion)
            except Exception as exc:  # pydantic's ValidationError names the field
                raise ValueError(f"motion: {exc}") from None
        data["motion"] = motion if motion is not None and motion.moving else None
        return data

    @model_validator(mode="after")
    def _rgb_for_reconstruction(self) -> DatasetSpec:
        if not self.render_rgb and "reconstructed" in self.geometries:
            raise ValueError("render_rgb: the reconstructed geometry needs RGB and LiDAR frames")
        return self

    @model_serializer(mode="plain")
    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (what Prefect stores as a flow's parameter); validates back into the
        same spec."""
        return {
            "frames_per_world": self.frames_per_world,
            "geometry": list(self.geometries),
            "radar": self.radar.to_dict(),
            "reconstruction": self.reconstruction.to_dict(),
            "world": self.world.model_dump(mode="json"),
            "rig": self.rig.model_dump(mode="json"),
            "seed": self.seed,
            "class_name": self.class_name,
            "labels": self.labels.model_dump(),
            "material_override": self.material_override,
            "export_label_range_m": (None if self.export_label_range_m is None
                                     else list(self.export_label_range_m)),
            "render_rgb": self.render_rgb,
            "motion": None if self.motion is None else self.motion.model_dump(mode="json"),
        }

    @property
    def moving(self) -> bool:
        """The rig moves while frames are taken (``motion`` with a speed above 0)."""
        return self.motion is not None and self.motion.moving


def _geometries(geometry: str | Sequence[str]) -> tuple[str, ...]:
    if isinstance(geometry, str):
        geometry = list(GEOMETRIES) if geometry == "both" else [geometry]
    out = tuple(dict.fromkeys(geometry))
    bad = [g for g in out if g not in GEOMETRIES]
    if bad or not out:
        raise ValueError(
            f"geometry: unknown mode(s) {bad or list(geometry)}; use 'ground_truth', "
            "'reconstructed' or 'both'"
        )
    return out


def resolve_reconstruction(value):
    """A :class:`~sim2radar.reconstruct.ReconstructionConfig` from itself, its dict, a YAML
    path, a preset name (``builtin``, ``oracle``, ``builtin-oracle-depth``) or the name of a
    bundled config (``production``: ``sim2radar.configs/reconstruct``); None: the built-in
    backends with LiDAR."""
    from sim2radar.reconstruct import ReconstructionConfig

    if value is None:
        return ReconstructionConfig()
    if isinstance(value, ReconstructionConfig):
        return value
    if isinstance(value, dict):
        try:
            return ReconstructionConfig.model_validate(value)
        except Exception as exc:
            raise ValueError(f"reconstruction config: {exc}") from None
    text = os.fspath(value)
    if looks_like_path(text):
        return ReconstructionConfig.from_yaml(text)
    try:
        return ReconstructionConfig.preset(text)
    except ValueError as exc:
        if text in bundled_configs("reconstruct"):  # e.g. "production" (user-supplied models)
            return ReconstructionConfig.from_yaml(config_path(text, "reconstruct"))
        raise ValueError(f"{exc}; bundled configs: {bundled_configs('reconstruct')} (or pass "
                         "a YAML path)") from None


def resolve_radar(value):
    """A :class:`~sim2radar.radar.RadarConfig` from itself, its dict, a YAML path or a preset
    name."""
    from sim2radar.radar import RadarConfig, load_radar_config

    if isinstance(value, RadarConfig):
        return value
    if isinstance(value, dict):
        return RadarConfig.model_validate(value)
    return load_radar_config(value)


def _rig_for_radar(rig, radar):
    """``rig`` with radar FOV/range fields set so its door flags describe ``radar``."""
    from sim2radar.worlds import radar_view

    want = (float(radar.azimuth_fov_deg), float(radar.elevation_fov_deg), float(radar.max_range_m))
    if np.allclose(radar_view(rig), want, rtol=1e-9, atol=1e-9):
        return rig  # unchanged -> the same world_frames keys as a plain worlds run
    return rig.model_copy(update={"radar_azimuth_fov_deg": want[0],
                                  "radar_elevation_fov_deg": want[1],
                                  "radar_max_range_m": want[2]})


def dataset_metadata(spec: DatasetSpec, geometry: str, domain: str | None = None) -> dict:
    """What a dataset export says about itself (``dataset.json``): its domain, radar and the
    rules its labels follow."""
    radar = spec.radar
    return {
        "domain": domain or (f"simulated ({radar.fidelity} radar {radar.name!r}, {geometry} "
                             "geometry" + (f", every material {spec.material_override}"
                                           if spec.material_override else "") + ")"),
        "radar": radar.name, "radar_fidelity": radar.fidelity,
        "radar_config_hash": radar.content_hash(),
        "material_override": spec.material_override,
        "label_rule": (f"doors the radar sees (>= {spec.labels.min_visibility:g} of the "
                       "doorway unoccluded, in FOV and range)"
                       + (" on the reconstructed geometry" if geometry == "reconstructed"
                          else "")),
        "class_name": spec.class_name, "run_seed": spec.seed,
        "range_resolution_m": radar.range_resolution_m,
        # the procedural rig's radar height above the floor (a capture run knows none)
        "radar_height_m": (float(spec.rig.radar_position_m[2]) if hasattr(spec, "rig")
                           else None),
        "rig_motion": ({"speed_mps": list(spec.motion.speed_mps),
                        "direction": "the rig's heading"}
                       if getattr(spec, "moving", False) else "static"),
    }


# ---------------------------------------------------------------------------------------------
# The generate YAML (configs/generate/*.yaml)
# ---------------------------------------------------------------------------------------------
#: Settings a generate YAML (``sim2radar generate --config``) may hold.
GENERATE_CONFIG_KEYS = {"worlds", "first_seed", "frames", "geometry", "radar", "reconstruction", "seed",
                "class_name", "world", "rig", "dataset", "labels", "material_override",
                "export_label_range_m", "poses", "motion"}


#: Whole-number settings and their smallest allowed value (None: any integer).
_INT_KEYS = {"worlds": 1, "first_seed": None, "frames": 1, "seed": None}


def load_generate_config(path: str | Path) -> dict[str, Any]:
    """Read a generate YAML; relative radar/reconstruction file paths resolve against its folder.

    Raises
    ------
    ValueError naming the file and the bad key.
    """
    path = config_path(path, "generate", what="generate config")
    if not path.is_file():
        raise ValueError(f"{path}: config file not found")
    try:
        doc = load_yaml(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: invalid YAML: {short_text(exc)}") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: expected a mapping of settings")
    unknown = sorted(set(doc) - GENERATE_CONFIG_KEYS)
    if unknown:
        raise ValueError(f"{path}: unknown key(s) {unknown}; allowed: {sorted(GENERATE_CONFIG_KEYS)}")
    for key in ("world", "rig"):
        if doc.get(key) is not None and not isinstance(doc[key], dict):
            raise ValueError(f"{path}: '{key}' must be a mapping of fields")
    for key, minimum in _INT_KEYS.items():
        if key in doc:
            doc[key] = whole_number(doc[key], path, key, minimum=minimum)
    for key in ("radar", "reconstruction"):
        value = doc.get(key)
        if isinstance(value, str) and value.endswith((".yaml", ".yml")) \
                and not Path(value).is_absolute():
            doc[key] = str((path.parent / value).resolve())
    return doc


def label_range(value: Any):
    """``"detector"`` -> the paper's PointPillars point-cloud range; a list or None as given."""
    from sim2radar.factory.labels import DEFAULT_POINT_CLOUD_RANGE_M

    return DEFAULT_POINT_CLOUD_RANGE_M if value == "detector" else value
