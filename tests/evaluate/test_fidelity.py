"""Where radar points are against the true geometry (sim2radar/evaluate/fidelity.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.evaluate.fidelity import (
    FidelityCounts,
    azimuth_coverage_deg,
    box_size_errors,
    points_per_box,
    surface_offsets,
)
from sim2radar.evaluate.reconstruction import match_boxes


def _wall_at(x_m: float):
    """First-hit query of an infinite wall x = x_m facing the radar (rays in the radar frame)."""
    def cast(origins, directions):
        d = np.asarray(directions, np.float64)
        t = (x_m - origins[:, 0]) / np.where(d[:, 0] > 1e-12, d[:, 0], np.nan)
        return np.where(d[:, 0] > 1e-12, t, np.inf)
    return cast


def test_surface_offset_is_range_minus_first_surface_along_the_ray():
    pts = np.array([[3.0, 0.0, 0.0, -40.0],          # on the wall
                    [5.0, 0.0, 0.0, -60.0],          # 2 m behind it (multipath)
                    [3.0, 3.0, 0.0, -50.0],          # on the wall at 45 deg
                    [-2.0, 0.0, 0.0, -70.0],         # behind the radar: no surface
                    [0.0, 0.0, 0.0, -80.0]])         # at the origin: undefined
    off = surface_offsets(pts, _wall_at(3.0))
    assert off.dtype == np.float32
    assert off[:3] == pytest.approx([0.0, 2.0, 0.0], abs=1e-5)
    assert np.isinf(off[3]) and np.isnan(off[4])
    assert surface_offsets(np.zeros((0, 4)), _wall_at(3.0)).shape == (0,)


def test_counts_pool_frames_and_count_a_point_with_no_surface_as_behind():
    offsets = [np.array([0.0, 2.0, np.inf, np.nan]), np.array([0.5, 1.5])]
    ranges = [np.array([3.0, 5.0, 9.0, 0.0]), np.array([8.0, 8.5])]
    c = FidelityCounts.of(offsets, ranges, max_range_m=10.0)
    assert (c.points, c.behind, c.beyond) == (5, 3, 1)       # NaN left out; far: > 8.5 m
    assert c.far_m == pytest.approx(8.5) and c.behind_m == 1.0
    assert c.behind_share == pytest.approx(0.6) and c.beyond_share == pytest.approx(0.2)
    assert c.to_dict()["points"] == 5
    assert math.isnan(FidelityCounts.of([], [], 10.0).behind_share)
    with pytest.raises(ValueError, match="surface offsets"):
        FidelityCounts.of([np.zeros(2)], [np.zeros(3)], 10.0)


def test_points_per_box_boxes_and_azimuths():
    box = np.array([[3.0, 0.0, 0.0, 1.0, 0.2, 2.0, math.pi / 2]])  # a door facing the radar
    pts = np.array([[3.0, 0.2, 0.5, 0], [3.05, -0.45, -0.9, 0], [3.3, 0.0, 0.0, 0],
                    [2.0, 2.0, 0.0, 0]])
    assert points_per_box(pts, box).tolist() == [2]
    lo, hi = azimuth_coverage_deg([pts, np.zeros((0, 4))])
    assert -10 < lo < 0 < 40 < hi <= 45.0   # percentiles 1 and 99 of 4 points
    assert all(math.isnan(v) for v in azimuth_coverage_deg([]))


def test_box_size_errors_of_matched_labels():
    gt = np.array([[3.0, 0.0, 1.0, 1.0, 0.2, 2.1, 0.0], [4.0, 3.0, 1.0, 0.9, 0.2, 2.0, 1.5]])
    pred = np.array([[3.1, 0.0, 1.0, 0.8, 0.17, 2.0, 0.0], [9.0, 9.0, 1.0, 1.0, 0.2, 2.0, 0.0]])
    m = match_boxes(pred, gt, 0.3)
    assert m["pairs"] == [(0, 0)] and m["tp"] == 1
    err = box_size_errors(pred, gt, m["pairs"])
    assert err.shape == (1, 4)
    assert err[0] == pytest.approx([-0.2, -0.03, -0.1, 0.1])
    assert box_size_errors(pred, gt, []).shape == (0, 4)
    same = match_boxes(gt, gt, 0.3)
    assert same["pairs"] == [(0, 0), (1, 1)]
