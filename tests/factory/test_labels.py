"""Door labels: a door the radar cannot see is not a label; the detector's range filter."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.factory.labels import (
    LabelConfig,
    boxes_in_point_cloud_range,
    doorway_samples,
    radar_visibility,
)

VIEW = (120.0, 40.0, 9.7)  # ti-mmwcas: azimuth FOV [deg], elevation FOV [deg], range [m]


def wall_caster(x_wall_m: float, y_max_m: float = np.inf):
    """First-hit distance of rays from the origin onto the plane x = x_wall (where y <= y_max)."""

    def cast(origins, directions):
        d = np.asarray(directions, float)
        with np.errstate(divide="ignore"):
            t = np.where(d[:, 0] > 0, x_wall_m / d[:, 0], np.inf)
        y = t * d[:, 1]
        return np.where(y <= y_max_m, t, np.inf)

    return cast


def door(x, y=0.0, heading=math.pi / 2):
    """A 0.9 m x 2.0 m doorway, 0.2 m deep, facing the radar (its width along y)."""
    return np.array([[x, y, 0.0, 0.9, 0.2, 2.0, heading]])


def test_samples_lie_on_the_mid_plane_inside_the_doorway():
    b = door(4.0, 1.0)
    p = doorway_samples(b, 5, 6, inset_m=0.05)
    assert p.shape == (1, 30, 3)
    np.testing.assert_allclose(p[0, :, 0], 4.0, atol=1e-9)          # mid-plane x = 4
    assert p[0, :, 1].min() == pytest.approx(1.0 - 0.40) and p[0, :, 1].max() == pytest.approx(1.4)
    assert p[0, :, 2].min() == pytest.approx(-0.95) and p[0, :, 2].max() == pytest.approx(0.95)


def test_door_in_front_of_a_wall_is_seen_and_behind_it_is_not():
    cast = wall_caster(6.0)
    front = radar_visibility(door(4.0), cast, VIEW)
    behind = radar_visibility(door(8.0), cast, VIEW)      # the corridor's end wall hides it
    assert front[0] == pytest.approx(1.0)
    assert behind[0] == 0.0


def test_the_leaf_itself_does_not_occlude_its_doorway():
    # a closed leaf 3 cm in front of the mid-plane, inside the box: still visible
    assert radar_visibility(door(5.0), wall_caster(4.97), VIEW)[0] == pytest.approx(1.0)
    # a wall 20 cm in front of the box's front face hides it
    assert radar_visibility(door(5.0), wall_caster(4.7), VIEW)[0] == 0.0


def test_half_hidden_door_has_half_visibility_and_the_threshold_decides():
    # a wall at x = 3 covering y <= 0 (as seen at x = 3): the left half of a door at y = 0 is free
    cast = wall_caster(3.0, y_max_m=0.0)
    vis = radar_visibility(door(5.0), cast, VIEW, LabelConfig(samples_along=8))
    assert vis[0] == pytest.approx(0.5)


def test_outside_fov_or_range_is_not_seen():
    nothing = wall_caster(np.inf)
    assert radar_visibility(door(1.0, 4.0), nothing, VIEW)[0] < 0.2      # ~76 deg azimuth
    assert radar_visibility(door(12.0), nothing, VIEW)[0] == 0.0          # beyond 9.7 m
    assert radar_visibility(door(-3.0), nothing, VIEW)[0] == 0.0          # behind the radar
    assert radar_visibility(np.zeros((0, 7)), nothing, VIEW).shape == (0,)


def test_point_cloud_range_filter_uses_box_centres():
    boxes = np.array([[2.0, 0.0, 0.0, 1, 0.2, 2, 0], [6.0, 0.0, 0.0, 1, 0.2, 2, 0],
                      [5.3, 5.0, 0.0, 1, 0.2, 2, 0]])
    keep = boxes_in_point_cloud_range(boxes, (-1.0, -5.2, -1.5, 5.4, 5.2, 2.5))
    assert keep.tolist() == [True, False, True]
    assert boxes_in_point_cloud_range(boxes, None).all()
    with pytest.raises(ValueError, match="max > min"):
        boxes_in_point_cloud_range(boxes, (1, 1, 1, 0, 0, 0))
