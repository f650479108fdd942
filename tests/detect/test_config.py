"""Config loading: YAML mirrors the defaults, paths resolve against the file, clear errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim2radar.detect.config import DetectConfig, ModelConfig, load_config

CONFIGS = Path(__file__).resolve().parents[2] / "configs" / "detect"


def test_paper_yaml_equals_defaults():
    cfg = load_config(CONFIGS / "pointpillars_door.yaml")
    assert cfg.model == ModelConfig(anchor=cfg.model.anchor)  # rotations written as 1.5707963
    assert cfg.model.anchor.size_m == ModelConfig().anchor.size_m
    assert cfg.optimization == DetectConfig().optimization
    assert cfg.augmentation == DetectConfig().augmentation
    assert cfg.data.root == (CONFIGS / "../../data/ifr").resolve()


@pytest.mark.parametrize("name", ["pointpillars_door_cpu_small.yaml",
                                  "pointpillars_door_sim_pretrain.yaml"])
def test_other_profiles_load(name):
    cfg = load_config(CONFIGS / name)
    assert cfg.data.root is not None and cfg.data.root.is_absolute()


def test_relative_paths_and_errors(tmp_path):
    (tmp_path / "sub").mkdir()
    y = tmp_path / "sub" / "c.yaml"
    y.write_text("data: {root: ../data}\npretrained_encoder: ckpt/last.pt\n")
    cfg = load_config(y)
    assert cfg.data.root == (tmp_path / "data").resolve()
    assert cfg.pretrained_encoder == (tmp_path / "sub" / "ckpt" / "last.pt").resolve()
    y.write_text("model: {voxel_size_m: [0.07, 0.05, 4.0]}\n")
    with pytest.raises(ValueError, match=r"(?s)c\.yaml.*whole number of voxel"):
        load_config(y)
    y.write_text("model: {num_point_feature: 4}\n")
    with pytest.raises(ValueError, match="num_point_feature"):
        load_config(y)
    with pytest.raises(FileNotFoundError):
        load_config(tmp_path / "missing.yaml")
