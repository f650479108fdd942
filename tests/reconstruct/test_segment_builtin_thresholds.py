"""The ``builtin`` segmenter's thresholds: named defaults, documented fields, validated options."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from sim2radar.reconstruct import ReconstructionConfig, build_backends
from sim2radar.reconstruct.segment_builtin import BuiltinSegments, SegmentGeometry
from sim2radar.reconstruct.segment_builtin_labels import vertical_label
from sim2radar.reconstruct.segment_builtin_thresholds import SegmenterThresholds

# The values the segmenter's steps used inline before they were named (the tuning on the
# procedural worlds). A change here is a change of the segmenter's output: it needs a new
# reconstruction stage version.
DOCUMENTED = {
    "min_valid_px": 16,
    "colour_blur_sigma_px": 0.8, "colour_blur_ref_width_px": 320.0, "orient_class_deg": 30.0,
    "depth_jump_rel": 0.02, "offset_step_per_m": 0.004, "min_region_px": 4,
    "level_normal_cos": 0.95, "level_min_px": 20, "floor_below_camera_m": 0.3,
    "ceiling_above_camera_m": 0.2, "level_fallback_pct": 1.0,
    "merge_passes": 3, "quick_fit_points": 1500, "door_like_max_vertical_cos": 0.4,
    "label_tilt_deg": 25.0, "red_hue": (8, 170), "red_min_saturation": 140, "red_min_value": 50,
    "extinguisher_min_red_frac": 0.5, "extinguisher_max_size_m": 1.2, "oblique_min_frac": 0.02,
    "oblique_wall_max_cos": 0.75, "below_ceiling_m": 0.1, "door_top_slack_m": 0.1,
    "door_min_fill": 0.5, "cut_door_min_width_m": 0.25, "cut_door_height_frac": 0.8,
    "fragment_max_bottom_m": 0.6, "fragment_min_width_m": 0.3, "fragment_min_height_m": 1.1,
    "fragment_min_fill": 0.6, "fragment_max_rms_m": 0.03, "handrail_min_length_m": 0.8,
    "handrail_max_height_m": 0.2, "handrail_bottom_m": (0.6, 1.2),
    "window_bottom_m": (0.4, 1.5), "window_width_m": (0.4, 3.0), "window_height_m": (0.4, 1.8),
    "window_min_fill": 0.6, "window_max_rms_m": 0.02, "window_min_brightness": 0.55,
    "wall_min_height_m": 1.0, "wall_min_width_m": 1.5,
    "wall_min_frac": 0.02, "wall_top_n": 8, "proud_open_px": 5, "proud_split_min_frac": 0.002,
    "proud_top_pct": 99.0, "proud_min_px": 100, "proud_min_points": 50,
    "proud_extent_margin_m": 0.1, "proud_within_frac": 0.8, "proud_front_pct": 10.0,
    "proud_min_front_m": 0.03, "parallel_deg": 10.0, "flush_min_px": 50,
    "flush_max_vertical_cos": 0.3, "flush_tol_m": 0.05, "flush_tol_per_m": 0.01,
    "flush_extent_margin_m": 0.1, "flush_on_frac": 0.8, "grow_min_px": 100,
    "grow_max_vertical_cos": 0.3,
    "below_floor_per_m": 0.01, "fill_ray_slope": 0.02, "floor_wall_min_frac": 0.01,
    "floor_wall_top_n": 8, "floor_wall_margin_m": 0.05, "min_segment_px": 10,
    "opening_wall_min_frac": 0.01, "opening_max_walls": 6, "opening_wall_extent_pct": 0.5,
    "opening_plane_tol_m": 0.04, "opening_max_behind_m": 4.0, "opening_inset_m": 0.02,
    "opening_below_floor_m": 0.1, "opening_above_wall_m": 0.05, "opening_open_px": 2,
    "opening_min_px": 30, "opening_min_frac": 0.001, "opening_frame_px": 6,
    "opening_extent_pct": 1.0, "recess_max_m": 0.35, "opening_door_width_slack_m": 0.15,
    "opening_window_bottom_m": (0.4, 1.4), "opening_window_height_m": (0.4, 2.0),
    "wall_min_points": 10, "wall_max_vertical_cos": 0.2, "wall_min_distance_m": 0.3,
    "wall_extent_pct": 1.0,
    "facade_wall_min_frac": 0.01, "facade_wall_top_n": 10, "facade_coplanar_deg": 10.0,
    "facade_coplanar_m": 0.1, "facade_wall_pad_m": 1.2, "facade_blur_sigma_px": 0.8,
}


def test_defaults_are_the_documented_values():
    assert dataclasses.asdict(SegmenterThresholds()) == DOCUMENTED
    assert BuiltinSegments().config.thresholds == SegmenterThresholds()


def test_every_field_is_documented_once_in_the_docstring():
    """Each field has its line in the class docstring, and the docstring names no field that
    does not exist."""
    doc = SegmenterThresholds.__doc__
    documented = re.findall(r"^    (\w+) :", doc, flags=re.MULTILINE)
    assert sorted(documented) == sorted(f.name for f in dataclasses.fields(SegmenterThresholds))


def test_unknown_threshold_is_an_error_naming_it():
    with pytest.raises(ValueError, match=r"segments\.options\.thresholds.*'wall_min_hieght_m'.*"
                                         r"known:.*wall_min_height_m"):
        BuiltinSegments(thresholds={"wall_min_hieght_m": 1.2})
    # the same from a reconstruction config (YAML)
    cfg = ReconstructionConfig.model_validate(
        {"segments": {"name": "builtin", "options": {"thresholds": {"bogus_m": 1.0}}}})
    with pytest.raises(ValueError, match=r"'bogus_m'"):
        build_backends(cfg)


@pytest.mark.parametrize(("key", "value"), [
    ("window_width_m", [3.0, 0.4]),  # reversed pair
    ("window_width_m", [0.4]),
    ("merge_passes", 2.5),  # a count must be whole
    ("wall_min_height_m", -1.0),
    ("wall_min_height_m", "1 m"),
    ("proud_min_px", True),
])
def test_bad_threshold_values_are_errors_naming_the_field(key, value):
    with pytest.raises(ValueError, match=rf"thresholds\.{key}: must be"):
        BuiltinSegments(thresholds={key: value})


def test_thresholds_from_yaml_lists_and_their_effect():
    """Lists (YAML) become pairs; a set threshold reaches its rule. A vertical panel 2.2 m wide
    and 1.2 m tall standing on the floor is too wide for a door and taller than
    ``wall_min_height_m`` (1 m): a wall's surface. Raised to 1.5 m (and ``wall_min_width_m`` to
    2.5 m), the same panel is clutter (a sideboard)."""
    seg = BuiltinSegments(thresholds={"window_width_m": [0.5, 2.5]})
    assert seg.config.thresholds.window_width_m == (0.5, 2.5)
    g = SegmentGeometry(50_000, np.array([3.0, 0.0, -0.65]), np.array([-1.0, 0.0, 0.0]), 0.01,
                        2.2, -1.25, -0.05, 0.95, "")
    assert vertical_label(BuiltinSegments().config, g, -1.25, 1.55, True)[0] == "wall"
    low = BuiltinSegments(thresholds={"wall_min_height_m": 1.5, "wall_min_width_m": 2.5})
    assert vertical_label(low.config, g, -1.25, 1.55, True)[0] == "clutter"
