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


def test_scalar_fields_refuse_lists_words_and_fractions():
    from sim2radar.configio import real_number, whole_number

    assert whole_number(4, "f.yaml", "frames") == 4 and whole_number(4.0, "f.yaml", "n") == 4
    for bad in ([1], "two", 2.5, True, None):
        with pytest.raises(ValueError, match=r"f.yaml: frames: must be a whole number.*"
                                             r"write e.g. 'frames: 1'"):
            whole_number(bad, "f.yaml", "frames", minimum=1)
    with pytest.raises(ValueError, match="f.yaml: frames: must be >= 1, got 0"):
        whole_number(0, "f.yaml", "frames", minimum=1)
    assert real_number(3, "k.yaml", "cx") == 3.0
    for bad in ([120.0], "x", False, float("nan")):
        with pytest.raises(ValueError, match=r"k.yaml: cx: must be a number \[px\]"):
            real_number(bad, "k.yaml", "cx", unit="px")
