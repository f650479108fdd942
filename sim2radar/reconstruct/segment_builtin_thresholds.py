"""Tuning thresholds of the ``builtin`` segmenter (:mod:`sim2radar.reconstruct.segment_builtin`).

Every number the segmenter's steps compare against, named, with its unit. The headline options
(``normal_thresh_deg``, ``door_width_m``, ``proud_m``, …) stay keyword options of
:class:`~sim2radar.reconstruct.segment_builtin.BuiltinSegments`; these are the rest, set in a
config as ``segments.options.thresholds`` (a mapping of field names). The defaults were tuned on
the procedural worlds at 640×480 (see the module docstring of ``segment_builtin`` for the
method); judge a change on worlds it was not tuned on.

Conventions: heights in the level frame (x forward, y left, z up, camera at the origin) [m];
``|n·z|`` of a unit normal is 1 for a horizontal plane, 0 for a vertical one; fractions of
"valid pixels" count the pixels with depth; percentiles ``p`` mean the pair (p, 100 − p) of a
robust extent. Label confidences (the scores a rule gives) are not thresholds and stay beside
their rules.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

__all__ = ["SegmenterThresholds", "config_from_options"]


@dataclasses.dataclass(frozen=True)
class SegmenterThresholds:
    """Thresholds of the ``builtin`` segmenter, grouped by the step that uses them.

    Attributes
    ----------
    **Input (step 1)**

    min_valid_px : int [px] — fewer pixels with depth is an input error.

    **Seed regions (step 3)**

    colour_blur_sigma_px : float [px] — least σ of the Gaussian that smooths the image before
        CIE-Lab colour distances are taken.
    colour_blur_ref_width_px : float [px] — σ grows as the image width over this (2 px at 640).
    orient_class_deg : float [deg] — pixel normals within this of the up direction face up (or
        down), within it of the horizontal are vertical, the rest oblique; neighbours of
        different classes are always split (a smoothed depth map bends gradually from a wall
        into the floor).
    depth_jump_rel : float — added to the relative depth jump ``tan(max_incidence_deg) / fx``
        that splits neighbours (depth noise).
    offset_step_per_m : float [m/m] — the plane-offset step ``offset_thresh_m`` grows by this
        per metre of depth (0.4 %).
    min_region_px : int [px] — least seed-region size, whatever ``min_region_frac`` gives.

    **Floor and ceiling levels (steps 2, 5)**

    level_normal_cos : float — pixels with ``|n·z|`` above this measure the floor (ceiling)
        level when no floor plane is known.
    level_min_px : int [px] — fewer such pixels give no level.
    floor_below_camera_m : float [m] — the floor lies at least this far below the camera
        (pixels and regions above it are not floor).
    ceiling_above_camera_m : float [m] — the ceiling lies at least this far above the camera.
    level_fallback_pct : float [%] — with no floor (ceiling) region, its level is this
        (100 − this) percentile of the point heights.

    **Merging (step 4)**

    merge_passes : int — rounds of merging adjacent coplanar regions.
    quick_fit_points : int — points sampled for the plane fits while merging and growing doors.
    door_like_max_vertical_cos : float — ``|n·z|`` below this makes a region vertical for the
        "two door-sized rectangles side by side stay apart" rule.

    **Labels (step 5)**

    label_tilt_deg : float [deg] — a region whose normal is within this of the vertical is
        horizontal (floor / ceiling), within this of the horizontal vertical.
    red_hue : (int, int) — OpenCV 8-bit hue (0–180, 2° steps): red below the first or above the
        second.
    red_min_saturation : int — least saturation (0–255) of a red pixel.
    red_min_value : int — least value (0–255) of a red pixel.
    extinguisher_min_red_frac : float — a region with more red pixels than this …
    extinguisher_max_size_m : float [m] — … and smaller than this is a fire extinguisher.
    oblique_min_frac : float — an oblique region with more than this fraction of the valid
        pixels (depth bent near the border) takes the label of the structure it leans towards.
    oblique_wall_max_cos : float — … a wall when its ``|n·z|`` is below this.
    below_ceiling_m : float [m] — a door (a doorway, a window opening) ends at least this
        below the ceiling.
    door_top_slack_m : float [m] — a door's measured top may lie this far outside
        ``door_height_m`` (the lintel and the depth's blur).
    door_min_fill : float — least fill (pixels / convex hull) of a door region.
    cut_door_min_width_m : float [m] — least width of a door region cut by the image border.
    cut_door_height_frac : float — such a door may be this fraction of the least door height.
    fragment_max_bottom_m : float [m] — a door fragment's bottom is at most this above the floor.
    fragment_min_width_m : float [m] — least width of a door fragment.
    fragment_min_height_m : float [m] — least height of a door fragment.
    fragment_min_fill : float — least fill of a door fragment.
    fragment_max_rms_m : float [m] — largest RMS distance of a door fragment's points to its
        plane.
    handrail_min_length_m : float [m] — least length of a handrail.
    handrail_max_height_m : float [m] — largest height of a handrail.
    handrail_bottom_m : (float, float) [m] — a handrail's bottom lies between these heights
        above the floor.
    window_bottom_m : (float, float) [m] — a window region's bottom (the sill) lies between
        these heights above the floor.
    window_width_m : (float, float) [m] — width of a window (regions and wall openings).
    window_height_m : (float, float) [m] — height of a window region.
    window_min_fill : float — least fill of a window region.
    window_max_rms_m : float [m] — largest RMS distance of a window's points to its plane.
    window_min_brightness : float — least mean HSV value (0–1) of a window region (glass shows
        daylight or reflections); a darker one is the upper part of a door or clutter.
    wall_min_height_m : float [m] — a vertical region taller than this is a wall …
    wall_min_width_m : float [m] — … and so is one wider than this.

    **Against the walls (step 5)**

    wall_min_frac : float — a ``wall`` region with at least this fraction of the valid pixels
        is a large wall for furniture (standing proud of it), wall pieces (flush with it) and
        door growing (the leaf's colour must differ from it).
    wall_top_n : int — only the this many largest regions are tried as large walls.
    proud_open_px : int [px] — morphological opening (square side) of the proud pixels split
        off a wall region.
    proud_split_min_frac : float — least size of such a split-off part, as a fraction of the
        image.
    proud_top_pct : float [%] — a region's top is this percentile of its heights.
    proud_min_px : int [px] — least pixel count of a region tested for standing proud.
    proud_min_points : int — least number of its points with depth.
    proud_extent_margin_m : float [m] — a proud region lies within the wall's extent widened
        by this …
    proud_within_frac : float — … with at least this fraction of its points.
    proud_front_pct : float [%] — percentile of the points' distance in front of the wall that
        must exceed ``proud_min_front_m`` (the region does not touch the wall).
    proud_min_front_m : float [m]
    parallel_deg : float [deg] — a region within this of its wall's orientation faces as the
        wall does (a cabinet's front), not turned like a leaf swung out of its doorway.
    flush_min_px : int [px] — least pixel count of a region tested for lying on a wall.
    flush_max_vertical_cos : float — ``|n·z|`` below this makes it vertical.
    flush_tol_m : float [m] — its points lie within this of the wall plane …
    flush_tol_per_m : float [m/m] — … plus this per metre of range …
    flush_extent_margin_m : float [m] — … and within the wall's extent widened by this …
    flush_on_frac : float — … for at least this fraction of them: it is that wall.
    grow_min_px : int [px] — least pixel count of a door fragment grown by colour.
    grow_max_vertical_cos : float — ``|n·z|`` below this for the fragment and the grown leaf.

    **Below the floor, above the ceiling (step 6)**

    below_floor_per_m : float [m/m] — ``below_floor_m`` grows by this per metre of range.
    fill_ray_slope : float — a pixel without depth is floor (ceiling) only when its level-frame
        viewing ray (camera z = 1) points down (up) by more than this.
    floor_wall_min_frac : float — large walls for this step: at least this fraction of the valid
        pixels …
    floor_wall_top_n : int — … among the this many largest regions.
    floor_wall_margin_m : float [m] — the ray must meet the floor (ceiling) at least this far
        in front of every large wall plane.
    min_segment_px : int [px] — least size of a segment made from such pixels, a wall opening's
        recess or a facade doorway.

    **Wall openings (step 7)**

    opening_wall_min_frac : float — walls searched for openings hold at least this fraction of
        the valid pixels …
    opening_max_walls : int — … the this many largest of them.
    opening_wall_extent_pct : float [%] — the wall's extent along itself is this percentile
        pair of its points.
    opening_plane_tol_m : float [m] — a point more than this behind the wall plane is seen
        through it; within it of the plane it lies on it (a coplanar wall region).
    opening_max_behind_m : float [m] — farthest a point seen through an opening lies behind it.
    opening_inset_m : float [m] — the ray crosses the wall plane at least this far inside the
        wall's extent.
    opening_below_floor_m : float [m] — … and at most this below the floor …
    opening_above_wall_m : float [m] — … and at most this above the wall's top.
    opening_open_px : int [px] — morphological opening (square side) of the candidate pixels.
    opening_min_px : int [px] — least pixel count of an opening …
    opening_min_frac : float — … and least fraction of the image.
    opening_frame_px : int [px] — the wall framing an opening is looked for within this many
        pixels left and right of it.
    opening_extent_pct : float [%] — an opening's width, bottom and top are this percentile pair.
    recess_max_m : float [m] — pixels of an opening at most this behind the wall are its leaf or
        pane (its segment); farther ones see the room beyond.
    opening_door_width_slack_m : float [m] — a door opening may be this much wider than
        ``door_width_m`` (the frame's outline).
    opening_window_bottom_m : (float, float) [m] — a window opening's bottom lies between these
        heights above the floor (the lower bound at least ``door_bottom_max_m``).
    opening_window_height_m : (float, float) [m] — height of a window opening.
    wall_min_points : int — a wall region needs at least this many points with depth for its
        plane (fewer: a region grown over pixels the LiDAR missed).
    wall_max_vertical_cos : float — a wall plane's ``|n·z|`` is below this.
    wall_min_distance_m : float [m] — a wall plane lies at least this far from the camera.
    wall_extent_pct : float [%] — a large wall's extent along itself is this percentile pair.

    **Facade doors (step 8)**

    facade_wall_min_frac : float — walls searched for door frames hold at least this fraction
        of the valid pixels …
    facade_wall_top_n : int — … among the this many largest regions.
    facade_coplanar_deg : float [deg] — wall regions whose normals are within this …
    facade_coplanar_m : float [m] — … and whose planes are within this of each other are one
        wall.
    facade_wall_pad_m : float [m] — the wall's extent is widened by this on both sides (a door
        may split its wall).
    facade_blur_sigma_px : float [px] — σ of the Gaussian before the image gradients.
    """

    # -- input (step 1) ----------------------------------------------------------------------
    min_valid_px: int = 16
    # -- seed regions (step 3) ---------------------------------------------------------------
    colour_blur_sigma_px: float = 0.8
    colour_blur_ref_width_px: float = 320.0
    orient_class_deg: float = 30.0
    depth_jump_rel: float = 0.02
    offset_step_per_m: float = 0.004
    min_region_px: int = 4
    # -- floor and ceiling levels (steps 2, 5) -----------------------------------------------
    level_normal_cos: float = 0.95
    level_min_px: int = 20
    floor_below_camera_m: float = 0.3
    ceiling_above_camera_m: float = 0.2
    level_fallback_pct: float = 1.0
    # -- merging (step 4) --------------------------------------------------------------------
    merge_passes: int = 3
    quick_fit_points: int = 1500
    door_like_max_vertical_cos: float = 0.4
    # -- labels (step 5) ---------------------------------------------------------------------
    label_tilt_deg: float = 25.0
    red_hue: tuple[int, int] = (8, 170)
    red_min_saturation: int = 140
    red_min_value: int = 50
    extinguisher_min_red_frac: float = 0.5
    extinguisher_max_size_m: float = 1.2
    oblique_min_frac: float = 0.02
    oblique_wall_max_cos: float = 0.75
    below_ceiling_m: float = 0.1
    door_top_slack_m: float = 0.1
    door_min_fill: float = 0.5
    cut_door_min_width_m: float = 0.25
    cut_door_height_frac: float = 0.8
    fragment_max_bottom_m: float = 0.6
    fragment_min_width_m: float = 0.3
    fragment_min_height_m: float = 1.1
    fragment_min_fill: float = 0.6
    fragment_max_rms_m: float = 0.03
    handrail_min_length_m: float = 0.8
    handrail_max_height_m: float = 0.2
    handrail_bottom_m: tuple[float, float] = (0.6, 1.2)
    window_bottom_m: tuple[float, float] = (0.4, 1.5)
    window_width_m: tuple[float, float] = (0.4, 3.0)
    window_height_m: tuple[float, float] = (0.4, 1.8)
    window_min_fill: float = 0.6
    window_max_rms_m: float = 0.02
    window_min_brightness: float = 0.55
    wall_min_height_m: float = 1.0
    wall_min_width_m: float = 1.5
    # -- against the walls: furniture, wall pieces, door leaves (step 5) ---------------------
    wall_min_frac: float = 0.02
    wall_top_n: int = 8
    proud_open_px: int = 5
    proud_split_min_frac: float = 0.002
    proud_top_pct: float = 99.0
    proud_min_px: int = 100
    proud_min_points: int = 50
    proud_extent_margin_m: float = 0.1
    proud_within_frac: float = 0.8
    proud_front_pct: float = 10.0
    proud_min_front_m: float = 0.03
    parallel_deg: float = 10.0
    flush_min_px: int = 50
    flush_max_vertical_cos: float = 0.3
    flush_tol_m: float = 0.05
    flush_tol_per_m: float = 0.01
    flush_extent_margin_m: float = 0.1
    flush_on_frac: float = 0.8
    grow_min_px: int = 100
    grow_max_vertical_cos: float = 0.3
    # -- below the floor, above the ceiling (step 6) -----------------------------------------
    below_floor_per_m: float = 0.01
    fill_ray_slope: float = 0.02
    floor_wall_min_frac: float = 0.01
    floor_wall_top_n: int = 8
    floor_wall_margin_m: float = 0.05
    min_segment_px: int = 10
    # -- wall openings (step 7) --------------------------------------------------------------
    opening_wall_min_frac: float = 0.01
    opening_max_walls: int = 6
    opening_wall_extent_pct: float = 0.5
    opening_plane_tol_m: float = 0.04
    opening_max_behind_m: float = 4.0
    opening_inset_m: float = 0.02
    opening_below_floor_m: float = 0.1
    opening_above_wall_m: float = 0.05
    opening_open_px: int = 2
    opening_min_px: int = 30
    opening_min_frac: float = 0.001
    opening_frame_px: int = 6
    opening_extent_pct: float = 1.0
    recess_max_m: float = 0.35
    opening_door_width_slack_m: float = 0.15
    opening_window_bottom_m: tuple[float, float] = (0.4, 1.4)
    opening_window_height_m: tuple[float, float] = (0.4, 2.0)
    wall_min_points: int = 10
    wall_max_vertical_cos: float = 0.2
    wall_min_distance_m: float = 0.3
    wall_extent_pct: float = 1.0
    # -- facade doors (step 8) ---------------------------------------------------------------
    facade_wall_min_frac: float = 0.01
    facade_wall_top_n: int = 10
    facade_coplanar_deg: float = 10.0
    facade_coplanar_m: float = 0.1
    facade_wall_pad_m: float = 1.2
    facade_blur_sigma_px: float = 0.8

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.type.startswith("tuple"):
                ok = (isinstance(value, tuple) and len(value) == 2
                      and all(_is_number(v) and v >= 0 for v in value) and value[0] <= value[1])
                want = "a pair [low, high] of numbers >= 0, low <= high"
            elif f.type == "int":
                ok = isinstance(value, int) and not isinstance(value, bool) and value >= 0
                want = "a whole number >= 0"
            else:
                ok = _is_number(value) and value >= 0
                want = "a number >= 0"
            if not ok:
                raise ValueError(f"segments.options.thresholds.{f.name}: must be {want}, "
                                 f"got {value!r}")


def _is_number(value: Any) -> bool:
    return (isinstance(value, int | float) and not isinstance(value, bool)
            and math.isfinite(value))


def config_from_options(cls: type, options: Mapping[str, Any] | None, where: str):
    """A frozen-dataclass config ``cls`` from an options mapping (e.g. YAML): lists become
    tuples; a key that is no field of ``cls`` is a ``ValueError`` naming ``where``, the key and
    the known fields."""
    options = dict(options or {})
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {unknown}; known: {sorted(known)}")
    return cls(**{key: tuple(v) if isinstance(v, list) else v for key, v in options.items()})
