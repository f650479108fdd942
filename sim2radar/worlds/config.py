"""Typed configuration of procedural worlds (:class:`WorldConfig`) and the sensor rig
(:class:`RigConfig`).

Both are frozen pydantic models: unknown fields are refused, every range is checked, and a bad
value fails with a message naming the field, e.g. ``corridor_width_m: lower bound 3.5 > upper
bound 3.0``. Ranges are ``(low, high)`` pairs sampled uniformly; probability tables map names to
weights that must sum to 1. YAML files hold the same fields (see ``configs/worlds/``)::

    world:
      corridor_length_m: [12, 25]
      door_state_probs: {closed: 0.6, ajar: 0.2, open: 0.2}
    rig:
      width: 320
      height: 240
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, ValidationError, field_validator, model_validator

from sim2radar.configio import DEFAULT_RADAR, config_path, read_yaml_mapping
from sim2radar.vocab import MATERIAL_CLASSES

__all__ = [
    "WALKING_SPEED_MPS",
    "WorldConfig",
    "RigConfig",
    "WorldConfigError",
    "load_worlds_config",
    "make_world_config",
    "make_rig_config",
    "resolve_world_configs",
    "radar_view",
    "LAYOUTS",
    "DOOR_STATES",
    "CLUTTER_KINDS",
    "MATERIAL_PRIOR_KEYS",
]

#: Layout families a world can take.
LAYOUTS = ("straight", "t_junction", "l_turn")
#: Door states.
DOOR_STATES = ("closed", "ajar", "open")
#: Clutter object kinds.
CLUTTER_KINDS = ("cabinet", "radiator", "bin")
#: Object kinds that draw their material from ``WorldConfig.material_priors``.
MATERIAL_PRIOR_KEYS = (
    "corridor_wall", "room_wall", "corridor_floor", "room_floor", "ceiling", "door_leaf",
    "door_frame", "door_handle", "window", "fire_extinguisher", "handrail", "cabinet", "radiator",
    "bin", "light",
)


class WorldConfigError(ValueError):
    """A world or rig configuration is invalid; the message names the file and field."""


Range = tuple[float, float]

_DEFAULT_PRIORS: dict[str, dict[str, float]] = {
    # Plausible building-practice priors (fire doors mostly metal, floors tile or concrete, ...).
    "corridor_wall": {"plasterboard": 0.55, "concrete": 0.35, "ceramic_tile": 0.10},
    "room_wall": {"plasterboard": 0.70, "concrete": 0.25, "wood": 0.05},
    "corridor_floor": {"ceramic_tile": 0.50, "concrete": 0.35, "plastic": 0.15},
    "room_floor": {"ceramic_tile": 0.30, "concrete": 0.20, "wood": 0.25, "fabric": 0.15,
                   "plastic": 0.10},
    "ceiling": {"plasterboard": 0.65, "concrete": 0.35},
    "door_leaf": {"metal": 0.65, "wood": 0.25, "glass": 0.10},
    "door_frame": {"metal": 0.80, "wood": 0.20},
    "door_handle": {"metal": 1.0},
    "window": {"glass": 1.0},
    "fire_extinguisher": {"metal": 1.0},
    "handrail": {"metal": 0.65, "wood": 0.25, "plastic": 0.10},
    "cabinet": {"metal": 0.50, "wood": 0.40, "plastic": 0.10},
    "radiator": {"metal": 1.0},
    "bin": {"plastic": 0.70, "metal": 0.30},
    "light": {"plastic": 1.0},
}


def _check_range(name: str, value: Range, *, low: float = 0.0, strict: bool = True) -> Range:
    lo, hi = (float(v) for v in value)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"{name}: bounds must be finite, got {value}")
    if lo > hi:
        raise ValueError(f"{name}: lower bound {lo} > upper bound {hi}; write [low, high]")
    if (lo <= low) if strict else (lo < low):
        raise ValueError(f"{name}: lower bound must be {'>' if strict else '>='} {low}, got {lo}")
    return lo, hi


def _check_probs(name: str, table: dict[str, float], known: tuple[str, ...]) -> dict[str, float]:
    unknown = sorted(set(table) - set(known))
    if unknown:
        raise ValueError(f"{name}: unknown key(s) {unknown}; known: {list(known)}")
    if any((not math.isfinite(p)) or p < 0 for p in table.values()):
        raise ValueError(f"{name}: probabilities must be finite and >= 0, got {table}")
    total = sum(table.values())
    if abs(total - 1.0) > 1e-6:
        raise ValueError(f"{name}: probabilities must sum to 1, got {total:.6g} ({table})")
    return {k: float(table[k]) for k in known if k in table}


class WorldConfig(BaseModel):
    """Parameters of world generation. Lengths in metres, angles in degrees.

    All lengths are snapped to the ``grid_m`` raster the layout is built on.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    layout_probs: dict[str, float] = {"straight": 0.35, "t_junction": 0.40, "l_turn": 0.25}
    corridor_length_m: Range = (10.0, 30.0)
    corridor_width_m: Range = (1.5, 3.0)
    branch_length_m: Range = (4.0, 12.0)
    ceiling_height_m: Range = (2.5, 3.2)
    wall_thickness_m: Range = (0.10, 0.20)
    room_width_m: Range = (2.5, 5.0)
    room_depth_m: Range = (2.5, 5.0)
    #: Probability that a free stretch of corridor wall gets a side room.
    room_probability: float = 0.65
    #: Spacing between neighbouring rooms along a corridor [m].
    room_gap_m: Range = (0.2, 3.0)
    #: Probability that a free stretch of corridor wall gets a closed "blind" door (stairwell,
    #: riser) with nothing modelled behind it.
    blind_door_probability: float = 0.25
    #: Probability of a closed door in a dead end's end wall.
    end_door_probability: float = 0.5
    door_double_probability: float = 0.3
    door_state_probs: dict[str, float] = {"closed": 0.5, "ajar": 0.25, "open": 0.25}
    door_single_width_m: Range = (0.80, 1.00)
    door_double_width_m: Range = (1.40, 1.80)
    door_height_m: Range = (2.00, 2.20)
    door_frame_width_m: float = 0.06
    door_leaf_thickness_m: float = 0.045
    ajar_deg: Range = (10.0, 40.0)
    open_deg: Range = (70.0, 95.0)
    #: Probability that an outer wall stretch (beyond it: outside) gets a window.
    window_probability: float = 0.5
    window_width_m: Range = (0.8, 2.0)
    window_sill_m: Range = (0.8, 1.0)
    window_top_m: Range = (1.9, 2.2)
    #: Fire extinguishers per corridor, drawn uniformly from the integer range.
    extinguishers_per_corridor: tuple[int, int] = (0, 2)
    #: Probability that a corridor side carries a handrail.
    handrail_probability: float = 0.4
    #: Expected clutter objects per 10 m of corridor wall (Poisson).
    clutter_per_10m: float = 1.5
    clutter_kind_probs: dict[str, float] = {"cabinet": 0.4, "radiator": 0.35, "bin": 0.25}
    #: Ceiling light spacing along corridors [m].
    light_spacing_m: Range = (2.5, 4.0)
    #: Radiance of the ceiling light panels (Mitsuba units).
    light_radiance: float = 6.0
    material_priors: dict[str, dict[str, float]] = _DEFAULT_PRIORS
    #: Raster cell used to build walls [m].
    grid_m: float = 0.05

    @field_validator(
        "corridor_length_m", "corridor_width_m", "branch_length_m", "ceiling_height_m",
        "wall_thickness_m", "room_width_m", "room_depth_m", "door_single_width_m",
        "door_double_width_m", "door_height_m", "window_width_m", "window_sill_m", "window_top_m",
        "light_spacing_m",
    )
    @classmethod
    def _positive_range(cls, v: Range, info) -> Range:
        return _check_range(info.field_name, v)

    @field_validator("room_gap_m", "ajar_deg", "open_deg")
    @classmethod
    def _nonneg_range(cls, v: Range, info) -> Range:
        return _check_range(info.field_name, v, strict=False)

    @field_validator("extinguishers_per_corridor")
    @classmethod
    def _int_range(cls, v: tuple[int, int], info) -> tuple[int, int]:
        lo, hi = _check_range(info.field_name, v, strict=False)
        return int(lo), int(hi)

    @field_validator(
        "room_probability", "blind_door_probability", "end_door_probability",
        "door_double_probability", "window_probability", "handrail_probability",
    )
    @classmethod
    def _probability(cls, v: float, info) -> float:
        if not 0.0 <= v <= 1.0:
            raise ValueError(f"{info.field_name}: must lie in [0, 1], got {v}")
        return v

    @field_validator("clutter_per_10m", "light_radiance")
    @classmethod
    def _nonneg(cls, v: float, info) -> float:
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{info.field_name}: must be finite and >= 0, got {v}")
        return v

    @field_validator("door_frame_width_m", "door_leaf_thickness_m", "grid_m")
    @classmethod
    def _pos(cls, v: float, info) -> float:
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{info.field_name}: must be finite and > 0, got {v}")
        return v

    @field_validator("layout_probs")
    @classmethod
    def _layouts(cls, v: dict[str, float]) -> dict[str, float]:
        return _check_probs("layout_probs", v, LAYOUTS)

    @field_validator("door_state_probs")
    @classmethod
    def _states(cls, v: dict[str, float]) -> dict[str, float]:
        return _check_probs("door_state_probs", v, DOOR_STATES)

    @field_validator("clutter_kind_probs")
    @classmethod
    def _clutter(cls, v: dict[str, float]) -> dict[str, float]:
        return _check_probs("clutter_kind_probs", v, CLUTTER_KINDS)

    @field_validator("material_priors")
    @classmethod
    def _priors(cls, v: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
        unknown = sorted(set(v) - set(MATERIAL_PRIOR_KEYS))
        if unknown:
            raise ValueError(
                f"material_priors: unknown object kind(s) {unknown}; known: "
                f"{list(MATERIAL_PRIOR_KEYS)}"
            )
        merged = dict(_DEFAULT_PRIORS)
        for kind, table in v.items():
            merged[kind] = _check_probs(f"material_priors.{kind}", table, MATERIAL_CLASSES[1:])
        return merged

    @model_validator(mode="after")
    def _consistent(self) -> WorldConfig:
        if self.window_sill_m[1] >= self.window_top_m[0]:
            raise ValueError(
                f"window_sill_m: upper bound {self.window_sill_m[1]} must be below "
                f"window_top_m's lower bound {self.window_top_m[0]}"
            )
        if self.door_height_m[1] + 0.2 > self.ceiling_height_m[0]:
            raise ValueError(
                f"door_height_m: upper bound {self.door_height_m[1]} leaves no lintel under "
                f"ceiling_height_m's lower bound {self.ceiling_height_m[0]} (need >= 0.2 m)"
            )
        if self.door_double_width_m[1] + 2 * self.door_frame_width_m > self.room_width_m[0] - 0.4:
            raise ValueError(
                f"door_double_width_m: upper bound {self.door_double_width_m[1]} does not fit "
                f"into room_width_m's lower bound {self.room_width_m[0]}"
            )
        return self


#: A person carrying the rig through a corridor walks at about this speed range [m/s] (min,
#: max; drawn per frame): the default motion of every procedural-world dataset, so the sim and
#: the reference radar take each frame at the same speed.
WALKING_SPEED_MPS = (0.5, 1.5)


class RigMotion(BaseModel):
    """How the rig moves while each frame is taken: along its heading (the radar's forward
    axis, levelled) at a speed drawn per frame uniformly from ``speed_mps`` [m/s]
    (:func:`sim2radar.worlds.trajectory.rig_velocity`); ``(0, 0)`` stands still. A person
    carrying the rig walks at ~0.5-1.5 m/s (:data:`WALKING_SPEED_MPS`). The signal-level radar
    turns the motion into each path's Doppler; the ray tracer's detector separates its returns
    into Doppler bins by direction (:func:`sim2radar.radar.detection.doppler_bins`).
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    speed_mps: tuple[float, float] = (0.0, 0.0)

    @field_validator("speed_mps")
    @classmethod
    def _speed(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo, hi = float(v[0]), float(v[1])
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo <= hi <= 10.0):
            raise ValueError(f"speed_mps: need 0 <= min <= max <= 10 [m/s], got {list(v)}")
        return lo, hi

    @property
    def moving(self) -> bool:
        return self.speed_mps[1] > 0.0


class RigConfig(BaseModel):
    """The sensor rig: pinhole camera, radar and sparse LiDAR, with their extrinsics.

    Mount positions are in the rig frame (x forward, y left, z up, origin on the floor) [m].
    All three sensors look along the rig's +x; the camera may pitch down by ``camera_pitch_deg``.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    width: int = 640
    height: int = 480
    hfov_deg: float = 65.0
    camera_position_m: tuple[float, float, float] = (0.0, 0.0, 1.25)
    #: Downward pitch of the camera [deg] (positive looks down).
    camera_pitch_deg: float = 3.0
    radar_preset: str = DEFAULT_RADAR
    radar_position_m: tuple[float, float, float] = (0.05, 0.0, 1.05)
    #: Radar azimuth / elevation field of view, full angles [deg], and maximum range [m] used
    #: for the door flags; ``None`` takes them from the ``radar_preset``'s RadarConfig.
    radar_azimuth_fov_deg: float | None = None
    radar_elevation_fov_deg: float | None = None
    radar_max_range_m: float | None = None
    lidar_position_m: tuple[float, float, float] = (0.0, 0.0, 1.45)
    lidar_beams: int = 16
    #: Lowest and highest beam elevation [deg] (VLP-16: -15..15).
    lidar_elevation_deg: tuple[float, float] = (-15.0, 15.0)
    lidar_azimuth_step_deg: float = 0.4
    lidar_max_range_m: float = 30.0
    #: Gaussian range noise of LiDAR returns [m] (0 = exact ray cast).
    lidar_range_noise_m: float = 0.0
    #: Samples per pixel of the path-traced RGB.
    spp: int = 16
    #: Path length of the RGB path tracer (2 = direct light only, 3 = one indirect bounce).
    max_depth: int = 3
    #: Denoise the RGB (edge-aware, guided by the exact normal/instance maps).
    denoise: bool = True
    #: A door counts as visible when at least this fraction of the image shows it.
    min_visible_fraction: float = 0.002

    @field_validator("width", "height", "spp", "max_depth")
    @classmethod
    def _pos_int(cls, v: int, info) -> int:
        if v <= 0:
            raise ValueError(f"{info.field_name}: must be > 0, got {v}")
        return v

    @field_validator("lidar_beams")
    @classmethod
    def _beams(cls, v: int) -> int:
        if not 1 <= v <= 128:
            raise ValueError(f"lidar_beams: must lie in [1, 128], got {v}")
        return v

    @field_validator("hfov_deg")
    @classmethod
    def _hfov(cls, v: float) -> float:
        if not 1.0 <= v <= 170.0:
            raise ValueError(f"hfov_deg: must lie in [1, 170], got {v}")
        return v

    @field_validator(
        "radar_azimuth_fov_deg", "radar_elevation_fov_deg", "radar_max_range_m",
        "lidar_azimuth_step_deg", "lidar_max_range_m",
    )
    @classmethod
    def _posf(cls, v: float | None, info) -> float | None:
        if v is None:
            return v
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{info.field_name}: must be finite and > 0, got {v}")
        return v

    @field_validator("lidar_range_noise_m", "min_visible_fraction")
    @classmethod
    def _nonnegf(cls, v: float, info) -> float:
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{info.field_name}: must be finite and >= 0, got {v}")
        return v

    @field_validator("lidar_elevation_deg")
    @classmethod
    def _elev(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo, hi = v
        if not -90 < lo <= hi < 90:
            raise ValueError(f"lidar_elevation_deg: need -90 < low <= high < 90, got {v}")
        return v


def radar_view(rig: RigConfig) -> tuple[float, float, float]:
    """Radar azimuth FOV [deg], elevation FOV [deg] and maximum range [m] for ``rig``: its
    explicit values, else those of ``rig.radar_preset`` (:func:`sim2radar.radar.load_radar_config`).
    """
    az, el, rng = rig.radar_azimuth_fov_deg, rig.radar_elevation_fov_deg, rig.radar_max_range_m
    if az is None or el is None or rng is None:
        from sim2radar.radar import load_radar_config

        radar = load_radar_config(rig.radar_preset)
        az = radar.azimuth_fov_deg if az is None else az
        el = radar.elevation_fov_deg if el is None else el
        rng = radar.max_range_m if rng is None else rng
    return float(az), float(el), float(rng)


def _format_validation(exc: ValidationError, where: str) -> str:
    lines = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"]) or "(root)"
        msg = err["msg"].removeprefix("Value error, ")
        msg = msg.removeprefix(f"{loc}: ")
        lines.append(f"{where}{loc}: {msg}")
    return "; ".join(lines)


def make_world_config(values: dict[str, Any] | None = None, *, source: str = "") -> WorldConfig:
    """Build a :class:`WorldConfig`, raising :class:`WorldConfigError` naming the bad field."""
    try:
        return WorldConfig(**(values or {}))
    except ValidationError as exc:
        prefix = f"{source}: world." if source else "world."
        raise WorldConfigError(_format_validation(exc, prefix)) from None


def make_rig_config(values: dict[str, Any] | None = None, *, source: str = "") -> RigConfig:
    """Build a :class:`RigConfig`, raising :class:`WorldConfigError` naming the bad field."""
    try:
        return RigConfig(**(values or {}))
    except ValidationError as exc:
        prefix = f"{source}: rig." if source else "rig."
        raise WorldConfigError(_format_validation(exc, prefix)) from None


def load_worlds_config(path: str | Path) -> tuple[WorldConfig, RigConfig]:
    """Read ``world:`` and ``rig:`` sections from a YAML file (both optional)."""
    path = config_path(path, "worlds", what="world config")
    doc = read_yaml_mapping(path, error=WorldConfigError,
                            expect="a mapping with 'world' and/or 'rig' sections")
    unknown = sorted(set(doc) - {"world", "rig"})
    if unknown:
        raise WorldConfigError(f"{path}: unknown section(s) {unknown}; allowed: world, rig")
    for key in ("world", "rig"):
        if doc.get(key) is not None and not isinstance(doc[key], dict):
            raise WorldConfigError(f"{path}: '{key}' must be a mapping of fields")
    return (
        make_world_config(doc.get("world"), source=str(path)),
        make_rig_config(doc.get("rig"), source=str(path)),
    )


def resolve_world_configs(world_cfg=None, rig=None) -> tuple[WorldConfig, RigConfig]:
    """(WorldConfig, RigConfig) from config objects, dicts of their fields or None (defaults);
    a bad field raises :class:`WorldConfigError` naming it."""
    if world_cfg is None:
        world_cfg = WorldConfig()
    elif isinstance(world_cfg, dict):
        world_cfg = make_world_config(world_cfg)
    if rig is None:
        rig = RigConfig()
    elif isinstance(rig, dict):
        rig = make_rig_config(rig)
    return world_cfg, rig
