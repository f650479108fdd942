"""Which doors are labels of a radar frame: visibility to the radar and the detector's range.

A door the radar cannot see is not a label. Its doorway box (``x y z dx dy dz heading``, radar
frame) is sampled on its mid-plane (a grid across the width ``dx`` and height ``dz``, inset from
the edges); a sample is **seen** when it lies inside the radar's azimuth/elevation field of view
and maximum range, and the first surface along the ray from the radar to it is not in front of
the doorway: ``t_hit >= |p| - (dy / 2 + occlusion_tolerance_m)`` (a closed leaf or the frame lies
within the box; an open doorway lets the ray pass further). The door's **visibility** is the
fraction of its samples seen; it is a label when ``visibility >= min_visibility``. The rule needs
only a first-hit distance query, so it applies to ground-truth and to reconstructed geometry
alike (:meth:`sim2radar.radar.RadarScene.first_hit_distance`).

The detector only sees points inside its point-cloud range (PointPillars: ``[-1.0, -5.2, -1.5,
5.4, 5.2, 2.5]`` m), so exports keep only labels whose centre lies inside it
(:func:`boxes_in_point_cloud_range`); OpenPCDet's own training mask
(``mask_boxes_outside_range``, any corner inside) is looser and still applies in training.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Annotated

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field

from sim2radar.boxes import as_boxes

__all__ = [
    "ClassName",
    "check_class_name",
    "LabelConfig",
    "doorway_samples",
    "radar_visibility",
    "scene_ray_caster",
    "boxes_in_point_cloud_range",
    "DEFAULT_POINT_CLOUD_RANGE_M",
]

#: PointPillars' point-cloud range of the paper (x_min, y_min, z_min, x_max, y_max, z_max) [m].
DEFAULT_POINT_CLOUD_RANGE_M: tuple[float, ...] = (-1.0, -5.2, -1.5, 5.4, 5.2, 2.5)


class LabelConfig(BaseModel):
    """How door labels are chosen for a radar frame (see the module docstring).

    Attributes
    ----------
    min_visibility : float — fraction of a doorway's samples the radar must see [0, 1].
    samples_along, samples_up : int — sample grid across the doorway's width and height.
    inset_m : float [m] — samples keep this distance from the doorway's edges.
    occlusion_tolerance_m : float [m] — a hit this far beyond the box's front half-depth still
        counts as the door (leaf swing, frame lips).
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    min_visibility: float = Field(0.2, ge=0.0, le=1.0)
    samples_along: int = Field(7, ge=1, le=64)
    samples_up: int = Field(9, ge=1, le=64)
    inset_m: float = Field(0.05, ge=0.0, le=0.5)
    occlusion_tolerance_m: float = Field(0.05, ge=0.0, le=1.0)


def doorway_samples(boxes, samples_along: int = 7, samples_up: int = 9,
                    inset_m: float = 0.05) -> np.ndarray:
    """(M, S, 3) float64 — sample points [m] on each box's mid-plane (``S = along * up``).

    The mid-plane spans the box's width ``dx`` (along its heading) and height ``dz``; samples
    form a regular grid inset by ``inset_m`` from the edges (collapsed to the centre line when
    the box is narrower than twice the inset).
    """
    b = as_boxes(boxes)
    m = len(b)
    if m == 0:
        return np.zeros((0, samples_along * samples_up, 3))

    def grid(size: np.ndarray, n: int) -> np.ndarray:  # (M, n) offsets from the centre
        half = np.maximum(size / 2 - inset_m, 0.0)
        t = np.linspace(-1.0, 1.0, n) if n > 1 else np.zeros(1)
        return half[:, None] * t[None, :]

    u = grid(b[:, 3], samples_along)  # along the heading
    w = grid(b[:, 5], samples_up)  # up
    uu = np.repeat(u, samples_up, axis=1)
    ww = np.tile(w, (1, samples_along))
    c, s = np.cos(b[:, 6])[:, None], np.sin(b[:, 6])[:, None]
    return np.stack([b[:, None, 0] + uu * c, b[:, None, 1] + uu * s, b[:, None, 2] + ww], -1)


def scene_ray_caster(scene, radar_to_world: np.ndarray | None = None
                     ) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """The ``first_hit_distance`` query of :func:`radar_visibility` for rays given in the radar
    frame, on a :class:`~sim2radar.radar.RadarScene` built in the world frame
    (``radar_to_world``, (4, 4)) or in the radar frame itself (None)."""
    if radar_to_world is None:
        return scene.first_hit_distance
    m = np.asarray(radar_to_world, np.float64)

    def cast(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        return scene.first_hit_distance(origins @ m[:3, :3].T + m[:3, 3],
                                        directions @ m[:3, :3].T)

    return cast


def radar_visibility(
    boxes_radar,
    first_hit_distance: Callable[[np.ndarray, np.ndarray], np.ndarray],
    view: Sequence[float],
    config: LabelConfig | None = None,
) -> np.ndarray:
    """Fraction of each doorway the radar sees (see the module docstring).

    Parameters
    ----------
    boxes_radar : (M, 7) — doorway boxes in the radar frame [m, rad].
    first_hit_distance : callable ``(origins (N, 3), directions (N, 3)) -> (N,)`` [m] — distance
        to the first surface along each ray (``inf`` on a miss), rays given in the radar frame.
    view : (azimuth_fov_deg, elevation_fov_deg, max_range_m) — the radar's full FOV [deg] and
        range [m].
    config : LabelConfig

    Returns
    -------
    (M,) float64 in [0, 1].
    """
    cfg = config or LabelConfig()
    b = as_boxes(boxes_radar)
    if len(b) == 0:
        return np.zeros(0)
    pts = doorway_samples(b, cfg.samples_along, cfg.samples_up, cfg.inset_m)
    m, s = pts.shape[:2]
    flat = pts.reshape(-1, 3)
    dist = np.linalg.norm(flat, axis=1)
    az_fov, el_fov, max_range = (float(v) for v in view)
    az = np.arctan2(flat[:, 1], flat[:, 0])
    el = np.arcsin(np.clip(flat[:, 2] / np.maximum(dist, 1e-12), -1.0, 1.0))
    in_view = ((dist > 1e-6) & (np.abs(az) <= math.radians(az_fov) / 2)
               & (np.abs(el) <= math.radians(el_fov) / 2) & (dist <= max_range))
    seen = np.zeros(len(flat), dtype=bool)
    if in_view.any():
        d = flat[in_view] / dist[in_view, None]
        t = np.asarray(first_hit_distance(np.zeros_like(d), d), dtype=np.float64)
        slack = np.repeat(b[:, 4] / 2 + cfg.occlusion_tolerance_m, s)[in_view]
        seen[in_view] = t >= dist[in_view] - slack
    return seen.reshape(m, s).mean(axis=1)


def boxes_in_point_cloud_range(boxes, point_cloud_range_m: Sequence[float] | None) -> np.ndarray:
    """(M,) bool — box centre inside ``[x_min, y_min, z_min, x_max, y_max, z_max]`` [m]
    (``None``: every box)."""
    b = as_boxes(boxes)
    if point_cloud_range_m is None:
        return np.ones(len(b), dtype=bool)
    r = np.asarray(point_cloud_range_m, dtype=np.float64)
    if r.shape != (6,) or np.any(r[3:] <= r[:3]):
        raise ValueError(f"point_cloud_range_m must be [x_min, y_min, z_min, x_max, y_max, "
                         f"z_max] with max > min, got {list(r)}")
    return np.all((b[:, :3] >= r[:3]) & (b[:, :3] <= r[3:]), axis=1)


def check_class_name(name: str) -> str:
    """``name`` if it can be a label class (one non-empty word: OpenPCDet's label files are
    whitespace-separated); ValueError otherwise."""
    if not name or any(c.isspace() for c in name):
        raise ValueError(f"class_name must be a non-empty word, got {name!r}")
    return name


#: A label class field of a pydantic model, checked by :func:`check_class_name`.
ClassName = Annotated[str, AfterValidator(check_class_name)]
