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


def test_a_bundled_config_is_found_by_name_from_any_folder(tmp_path, monkeypatch):
    """Names resolve through the package (importlib.resources), not the working directory;
    a path is taken as it is, and an unknown name lists what is bundled."""
    from sim2radar.configio import bundled_configs, config_path
    from sim2radar.experiment.profiles import load_profile
    from sim2radar.factory.spec import resolve_reconstruction

    monkeypatch.chdir(tmp_path)  # no configs/ here
    assert {"demo", "paper", "smoke", "study"} <= set(bundled_configs("experiment"))
    path = config_path("demo", "experiment")
    assert path.is_file() and path.parent.name == "experiment"
    assert load_profile("demo").name == "demo"
    assert config_path(tmp_path / "mine.yaml", "experiment") == tmp_path / "mine.yaml"
    with pytest.raises(FileNotFoundError, match=r"no bundled experiment profile 'nope'.*demo"):
        load_profile("nope")
    # a reconstruction config by name: the presets, or a bundled file (production's models)
    assert resolve_reconstruction("production").depth.name == "moge"
    assert resolve_reconstruction("builtin").depth.name == "lidar"
    with pytest.raises(ValueError, match="bundled configs:.*production"):
        resolve_reconstruction("nope")
