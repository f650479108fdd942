"""The ``prior`` material backend: semantic prior × colour/texture rules."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct.materials_prior import PRIORS, PriorMaterials, segment_features
from sim2radar.reconstruct.types import DepthResult, FrameInput, Segments
from sim2radar.vocab import MATERIAL_CLASSES

H, W = 64, 96
RNG = np.random.default_rng(0)


def _patch(kind: str) -> np.ndarray:
    """A (H, W, 3) uint8 texture of one finish, with 2 % sensor noise."""
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    if kind == "wood":
        base = np.array([0.55, 0.36, 0.18])
        mod = 1 + 0.25 * np.sin(2 * np.pi * (y / 6 + 0.3 * np.sin(x / 15)))
    elif kind == "tiles":
        base = np.array([0.6, 0.6, 0.58])
        grout = (np.minimum(x % 16, y % 16) < 1.5)
        mod = np.where(grout, 0.45, 1.0)
    elif kind == "concrete":
        base = np.array([0.45, 0.45, 0.44])
        mod = 1 + 0.5 * np.sin(x / 4.0) * np.sin(y / 3.5) + 0.03 * RNG.standard_normal((H, W))
    elif kind == "paint":
        base = np.array([0.8, 0.79, 0.75])
        mod = np.ones((H, W))
    elif kind == "grey_paint":
        base = np.array([0.3, 0.34, 0.4])
        mod = np.ones((H, W))
    else:
        raise ValueError(kind)
    img = base * mod[..., None] * (1 + 0.01 * RNG.standard_normal((H, W, 1)))
    return (np.clip(img, 0, 1) * 255).astype(np.uint8)


def _label(kind: str, label: str) -> str:
    rgb = _patch(kind)
    frame = FrameInput(rgb, CameraIntrinsics.from_fov(W, H, 60))
    seg = Segments(np.zeros((H, W), np.int32), (label,), np.ones(1, np.float32))
    out = PriorMaterials().label(frame, DepthResult(np.ones((H, W), np.float32)), seg)
    assert len(out) == 1 and out[0].material in MATERIAL_CLASSES and 0 < out[0].confidence <= 1
    assert out[0].reason
    return out[0].material


@pytest.mark.parametrize(
    "kind,label,expected",
    [
        ("grey_paint", "door", "metal"),       # painted fire door: the prior
        ("wood", "door", "wood"),              # wood hue + grain
        ("tiles", "floor", "ceramic_tile"),    # grout lines
        ("concrete", "wall", "concrete"),      # grey mottling
        ("paint", "wall", "plasterboard"),     # smooth paint
        ("paint", "window", "glass"),
        ("grey_paint", "fire_extinguisher", "metal"),
        ("paint", "ceiling", "plasterboard"),
    ],
)
def test_prior_and_rules(kind, label, expected):
    assert _label(kind, label) == expected


def test_features_measure_grain_and_grout():
    full = np.ones((H, W), bool)
    wood = segment_features(_patch("wood"), full)
    tiles = segment_features(_patch("tiles"), full)
    paint = segment_features(_patch("paint"), full)
    assert 12 <= wood.hue_deg <= 48 and wood.coherence > 0.5
    assert tiles.grout_frac > 0.05 and paint.grout_frac < 0.01
    assert paint.lf_contrast < 0.02 and segment_features(_patch("concrete"), full).lf_contrast > 0.12


def test_priors_are_distributions_over_the_vocabulary():
    for label, row in PRIORS.items():
        assert set(row) <= set(MATERIAL_CLASSES), label
        assert sum(row.values()) == pytest.approx(1.0, abs=1e-6), label


def test_prior_override_and_validation():
    backend = PriorMaterials({"door": {"wood": 1.0}}, use_rules=False)
    post, fired = backend.posterior("door", segment_features(_patch("grey_paint"), np.ones((H, W), bool)))
    assert post == {"wood": 1.0} and fired == []
    with pytest.raises(ValueError, match="unknown material"):
        PriorMaterials({"door": {"steel": 1.0}})
    with pytest.raises(ValueError, match="unknown label"):
        PriorMaterials({"doorway": {"metal": 1.0}})
