"""Tests for sim2radar/configio.py: every config loader's file-level errors name the file."""

import pytest

from sim2radar.configio import read_yaml_mapping
from sim2radar.radar import RadarConfigError, load_radar_config


def test_file_level_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.yaml: intrinsics file not found"):
        read_yaml_mapping(tmp_path / "nope.yaml", what="intrinsics file",
                          missing_error=FileNotFoundError)
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [1, 2\n")
    with pytest.raises(ValueError, match="bad.yaml: invalid YAML"):
        read_yaml_mapping(bad)
    seq = tmp_path / "seq.yaml"
    seq.write_text("- 1\n- 2\n")
    with pytest.raises(RadarConfigError, match="seq.yaml: expected a mapping of radar fields"):
        load_radar_config(seq)
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    assert read_yaml_mapping(empty) == {}
