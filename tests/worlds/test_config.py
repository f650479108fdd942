"""World/rig configuration: defaults valid, bad values name the field, YAML loading."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from sim2radar.worlds import (
    RigConfig,
    WorldConfig,
    WorldConfigError,
    load_worlds_config,
    make_rig_config,
    make_world_config,
    radar_view,
)


def test_defaults_are_valid_and_frozen():
    cfg = WorldConfig()
    assert cfg.corridor_width_m == (1.5, 3.0)
    assert abs(sum(cfg.door_state_probs.values()) - 1) < 1e-9
    with pytest.raises(ValidationError, match="frozen"):
        cfg.grid_m = 0.1


@pytest.mark.parametrize(
    "values, field",
    [
        ({"corridor_width_m": [3.5, 3.0]}, "corridor_width_m"),
        ({"corridor_length_m": [-1, 10]}, "corridor_length_m"),
        ({"door_state_probs": {"closed": 0.5}}, "door_state_probs"),
        ({"door_state_probs": {"closed": 0.5, "wide": 0.5}}, "door_state_probs"),
        ({"material_priors": {"door_leaf": {"metal": 0.5, "cheese": 0.5}}},
         "material_priors"),
        ({"material_priors": {"spaceship": {"metal": 1.0}}}, "material_priors"),
        ({"room_probability": 1.5}, "room_probability"),
        ({"colour": "red"}, "colour"),
        ({"door_height_m": [2.0, 3.0], "ceiling_height_m": [2.5, 3.0]}, "door_height_m"),
    ],
)
def test_bad_world_config_names_the_field(values, field):
    with pytest.raises(WorldConfigError, match=field):
        make_world_config(values)


@pytest.mark.parametrize(
    "values, field",
    [({"width": 0}, "width"), ({"hfov_deg": 200}, "hfov_deg"), ({"lidar_beams": 0}, "lidar_beams"),
     ({"spp": -1}, "spp"), ({"lidar_elevation_deg": [10, -10]}, "lidar_elevation_deg")],
)
def test_bad_rig_config_names_the_field(values, field):
    with pytest.raises(WorldConfigError, match=rf"rig\.{field}"):
        make_rig_config(values)


def test_yaml_config_round_trip_and_errors(tmp_path):
    good = tmp_path / "w.yaml"
    good.write_text("world:\n  corridor_length_m: [12, 14]\nrig:\n  width: 320\n  height: 240\n")
    world, rig = load_worlds_config(good)
    assert world.corridor_length_m == (12.0, 14.0) and rig.width == 320
    bad = tmp_path / "bad.yaml"
    bad.write_text("world:\n  door_single_width_m: [1.2, 0.9]\n")
    with pytest.raises(WorldConfigError, match=r"bad\.yaml: world\.door_single_width_m"):
        load_worlds_config(bad)
    section = tmp_path / "s.yaml"
    section.write_text("worlds: {}\n")
    with pytest.raises(WorldConfigError, match="unknown section"):
        load_worlds_config(section)
    with pytest.raises(WorldConfigError, match="not found"):
        load_worlds_config(tmp_path / "missing.yaml")


def test_radar_view_from_preset_and_override():
    az, el, rng = radar_view(RigConfig())
    assert az == pytest.approx(120.0) and el > 0 and rng > 1.0
    assert radar_view(RigConfig(radar_max_range_m=5.0))[2] == 5.0
