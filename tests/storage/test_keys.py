"""Content keys: equal iff (stage, stage version, inputs, resolved config) are equal."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim2radar.storage import KEY_LENGTH, canonical_json, content_key

BASE = dict(
    stage="radar_points",
    stage_version=1,
    inputs={"scene": "a" * 20},
    config={"bandwidth_hz": 3.95e9, "rays": {"az": 512, "el": 64}, "seed": 0},
)


def key(**over):
    return content_key(**{**BASE, **over})


def test_key_is_deterministic_hex_and_order_insensitive():
    k = key()
    assert len(k) == KEY_LENGTH and all(c in "0123456789abcdef" for c in k)
    reordered = {"seed": 0, "rays": {"el": 64, "az": 512}, "bandwidth_hz": 3.95e9}
    assert key(config=reordered) == k


@pytest.mark.parametrize(
    "change",
    [
        {"stage_version": 2},
        {"stage": "scene_meshes"},
        {"inputs": {"scene": "b" * 20}},
        {"inputs": {"scene": "a" * 20, "extra": "c" * 20}},
        {"config": {**BASE["config"], "bandwidth_hz": 4.0e9}},
        {"config": {**BASE["config"], "rays": {"az": 513, "el": 64}}},
        {"config": {**BASE["config"], "seed": 1}},
    ],
)
def test_key_changes_when_anything_that_matters_changes(change):
    assert key(**change) != key()


def test_numpy_and_python_values_hash_alike():
    cfg_np = {
        "bandwidth_hz": np.float64(3.95e9),
        "rays": {"az": np.int64(512), "el": 64},
        "seed": np.int32(0),
    }
    assert key(config=cfg_np) == key()
    # float noise far below any physical tolerance does not change the key
    assert key(config={**BASE["config"], "bandwidth_hz": 3.95e9 * (1 + 1e-15)}) == key()
    # arrays keep their dtype in the hash: int vs float arrays differ
    assert canonical_json(np.arange(3)) != canonical_json(np.arange(3.0))
    assert canonical_json(Path("a/b")) == '"a/b"'


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="stage must be lowercase"):
        content_key(stage="Radar Points", stage_version=1)
    with pytest.raises(ValueError, match="stage_version"):
        content_key(stage="radar_points", stage_version=-1)
    with pytest.raises(TypeError, match=r"config\.fn"):
        content_key(stage="radar_points", stage_version=1, config={"fn": object()})
