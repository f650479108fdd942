"""Settings of the ``builtin`` segmenter and the state of one call.

The segmenter (:mod:`sim2radar.reconstruct.segment_builtin`) is module-level step functions
over two values:

- :class:`SegmenterConfig` — frozen: the headline options (the keyword options of
  :class:`~sim2radar.reconstruct.segment_builtin.BuiltinSegments`), the facade search's
  :class:`~sim2radar.reconstruct.facade.FacadeConfig` and every other threshold
  (:class:`~sim2radar.reconstruct.segment_builtin_thresholds.SegmenterThresholds`);
- :class:`SegmentContext` — frozen, one per frame: the level-frame points, the smoothed colour,
  the image, the camera and, once the regions are labelled, the floor and ceiling levels.

Nothing of a call is kept after it returns, so one segmenter serves any number of threads.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from typing import Any

import numpy as np

from sim2radar.boxes import DOOR_THICKNESS_M
from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct.backproject import finite_rows
from sim2radar.reconstruct.facade import FacadeConfig
from sim2radar.reconstruct.segment_builtin_thresholds import (
    SegmenterThresholds,
    config_from_options,
)

__all__ = ["SegmentContext", "SegmenterConfig"]


@dataclasses.dataclass(frozen=True)
class SegmenterConfig:
    """Options of the ``builtin`` segmenter (the method: module docstring of
    :mod:`~sim2radar.reconstruct.segment_builtin`).

    Defaults suit 640×480 corridor images and scale with size. Build it from a config's
    ``segments.options`` with :meth:`from_options` (YAML lists become pairs, the nested
    ``facade_options`` and ``thresholds`` mappings their configs).

    Attributes
    ----------
    normal_thresh_deg : float [deg] — neighbours whose normals turn by more are split (step 3).
    colour_thresh : float [ΔE*ab] — neighbours whose smoothed colours differ by more are split.
    max_incidence_deg : float [deg] — the steepest incidence of a continuous surface; a larger
        relative depth jump between neighbours splits them.
    min_region_frac : float — least seed-region size, as a fraction of the image.
    merge_normal_deg : float [deg] — adjacent regions with normals within this … (step 4)
    merge_offset_m : float [m] — … plane offsets within this …
    merge_colour_thresh : float [ΔE*ab] — … and mean colours within this are merged.
    door_width_m : (float, float) [m] — width of a door leaf.
    door_height_m : (float, float) [m] — height of a door leaf: leaves are 1.98–2.13 m in the
        common standards (DIN 18101, US 6'8"–7'0") and the measured top adds up to ~0.1 m; a
        taller rectangle standing on the floor is a wall's surface (e.g. a wall facing the
        camera and cut by the image's top border).
    floor_tolerance_m : float [m] — a region within this of the floor (ceiling) level stands on
        it (is it).
    offset_thresh_m : float [m] — plane-offset step between neighbours that splits them (a door a
        few cm proud of or set into its wall), plus 0.4 % of the depth.
    door_thickness_m : float [m] — depth of the doorway boxes measured from wall openings
        (:data:`sim2radar.boxes.DOOR_THICKNESS_M`).
    fill_no_depth : bool — pixels without depth join the nearest region (and below the lowest
        measured pixel of their column, the floor).
    below_floor_m : float [m] — points this far below the floor (above the ceiling), plus 1 % of
        their range, are floor (ceiling) (step 6).
    door_partial : bool — tall planar fragments standing near the floor are doors, and door
        leaves are grown from them by colour.
    door_bottom_max_m : float [m] — an opening of door height whose bottom is lower than this is
        a door, higher a window.
    grow_colour : float [ΔE*ab] — colour step that bounds a door leaf grown from its lower
        fragment.
    proud_m : (float, float) [m] — a vertical region this far in front of a large wall is
        furniture.
    proud_split : bool — such pixels inside a wall's own region are split off too.
    lidar_floor : bool — floor plane and up from the raw LiDAR returns when given (step 2).
    facade : bool — door frames on rectified wall planes (step 8).
    facade_config : FacadeConfig — options of that search.
    thresholds : SegmenterThresholds — every other threshold of the steps, with its unit.
    """

    normal_thresh_deg: float = 20.0
    colour_thresh: float = 14.0
    max_incidence_deg: float = 84.0
    min_region_frac: float = 3e-4
    merge_normal_deg: float = 12.0
    merge_offset_m: float = 0.06
    merge_colour_thresh: float = 12.0
    door_width_m: tuple[float, float] = (0.55, 2.0)
    door_height_m: tuple[float, float] = (1.85, 2.3)
    floor_tolerance_m: float = 0.25
    offset_thresh_m: float = 0.015
    door_thickness_m: float = DOOR_THICKNESS_M
    fill_no_depth: bool = True
    below_floor_m: float = 0.08
    door_partial: bool = True
    door_bottom_max_m: float = 0.75
    grow_colour: float = 15.0
    proud_m: tuple[float, float] = (0.12, 0.7)
    proud_split: bool = True
    lidar_floor: bool = True
    facade: bool = True
    facade_config: FacadeConfig = FacadeConfig()
    thresholds: SegmenterThresholds = SegmenterThresholds()

    def __post_init__(self) -> None:
        # the options arrive from YAML: numbers as int or float, pairs as lists
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.type == "float":
                value = float(value)
            elif f.type == "bool":
                value = bool(value)
            elif f.type.startswith("tuple"):
                value = tuple(float(x) for x in value)
            object.__setattr__(self, f.name, value)

    @classmethod
    def from_options(cls, *, facade_options: Mapping[str, Any] | None = None,
                     thresholds: Mapping[str, Any] | None = None,
                     **options: Any) -> SegmenterConfig:
        """The config of a backend's keyword options (``segments.options`` of a
        reconstruction config): the headline options by name, ``facade_options`` a mapping of
        :class:`~sim2radar.reconstruct.facade.FacadeConfig` fields and ``thresholds`` one of
        :class:`~sim2radar.reconstruct.segment_builtin_thresholds.SegmenterThresholds` fields.

        Raises
        ------
        TypeError — an option that is no field (the pipeline reports the backend's options).
        ValueError — a misspelt field of ``facade_options`` or ``thresholds`` (named, with the
            known fields), or a threshold out of its range.
        """
        return cls(**options,
                   facade_config=config_from_options(FacadeConfig, facade_options,
                                                     "segments.options.facade_options"),
                   thresholds=config_from_options(SegmenterThresholds, thresholds,
                                                  "segments.options.thresholds"))


@dataclasses.dataclass(frozen=True, eq=False)
class SegmentContext:
    """What the steps of one call share: the frame in the level frame (x forward, y left,
    z up, origin at the camera) and the levels found in it.

    Made by :func:`~sim2radar.reconstruct.segment_builtin.segment_frame` for each frame (tests
    make one over a synthetic point grid); the steps read it and return their results, none
    changes it. The levels are filled in by :meth:`with_levels` once the regions are labelled.

    Attributes
    ----------
    config : SegmenterConfig
    points_level : (H, W, 3) float [m] — the back-projected depth in the level frame; NaN where
        there is no depth.
    pixel_angle_rad : float or None [rad] — angle of one pixel (1 / fx); sets the gap that
        splits a region's points along its plane
        (:func:`~sim2radar.reconstruct.segment_builtin_geometry.footprint_gap_m`); None: the
        least gap.
    lab : (H, W, 3) float32 or None — the smoothed image in CIE-Lab (L* in [0, 100]).
    rgb : (H, W, 3) uint8 or None — the image.
    rotation : (3, 3) float64 or None — camera frame -> level frame.
    intrinsics : CameraIntrinsics or None
    floor_z_m, ceiling_z_m : float or None [m] — floor and ceiling levels (z in the level frame).
    """

    config: SegmenterConfig
    points_level: np.ndarray
    pixel_angle_rad: float | None = None
    lab: np.ndarray | None = None
    rgb: np.ndarray | None = None
    rotation: np.ndarray | None = None
    intrinsics: CameraIntrinsics | None = None
    floor_z_m: float | None = None
    ceiling_z_m: float | None = None

    @property
    def thresholds(self) -> SegmenterThresholds:
        return self.config.thresholds

    @functools.cached_property
    def valid(self) -> np.ndarray:
        """(H, W) bool — pixels with depth (every coordinate of ``points_level`` finite);
        made once per context, as the steps all read it."""
        valid = finite_rows(self.points_level)
        valid.flags.writeable = False  # shared by every step: none may change it
        return valid

    def with_levels(self, floor_z_m: float, ceiling_z_m: float) -> SegmentContext:
        """This context with the floor and ceiling levels [m]."""
        return dataclasses.replace(self, floor_z_m=floor_z_m, ceiling_z_m=ceiling_z_m)
