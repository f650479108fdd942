"""The ``builtin`` segmenter's frozen config and per-call context
(``reconstruct.segment_builtin_config``): options from YAML, and a segmenter that keeps nothing
of a call, so one instance serves many threads."""

from __future__ import annotations

import dataclasses
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from sim2radar.reconstruct import ReconstructionConfig, build_backends
from sim2radar.reconstruct.facade import FacadeConfig
from sim2radar.reconstruct.segment_builtin import BuiltinSegments, segment_frame
from sim2radar.reconstruct.segment_builtin_config import SegmentContext, SegmenterConfig
from sim2radar.reconstruct.segment_builtin_thresholds import SegmenterThresholds
from sim2radar.reconstruct.synthetic import corridor_frame
from sim2radar.reconstruct.types import DepthResult, FrameInput


def test_options_from_yaml_become_a_frozen_config():
    """YAML gives ints for floats and lists for pairs; the config holds floats and tuples, the
    nested mappings become their configs, and it cannot be changed after it is made."""
    cfg = SegmenterConfig.from_options(normal_thresh_deg=25, door_width_m=[0.6, 1.8],
                                       proud_split=0, facade_options={"lintel_cover": 0.5},
                                       thresholds={"window_width_m": [0.5, 2.5]})
    assert cfg.normal_thresh_deg == 25.0 and isinstance(cfg.normal_thresh_deg, float)
    assert cfg.door_width_m == (0.6, 1.8) and cfg.proud_split is False
    assert cfg.facade_config == FacadeConfig(lintel_cover=0.5)
    assert cfg.thresholds == SegmenterThresholds(window_width_m=(0.5, 2.5))
    assert SegmenterConfig.from_options() == SegmenterConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.proud_split = True
    assert BuiltinSegments(door_width_m=[0.6, 1.8]).config == SegmenterConfig(door_width_m=(0.6, 1.8))


def test_an_unknown_option_is_reported_by_the_pipeline():
    """A misspelt headline option fails when the backends are built, naming the options."""
    with pytest.raises(TypeError, match="normal_thresh"):
        SegmenterConfig.from_options(normal_thresh=20)
    cfg = ReconstructionConfig.model_validate({"segments": {"name": "builtin",
                                                            "options": {"normal_thresh": 20}}})
    with pytest.raises(ValueError, match=r"backend 'builtin': bad options.*normal_thresh"):
        build_backends(cfg)


def test_context_levels_are_a_new_context():
    """The levels found after labelling go into a copy; the context a step was given does not
    change."""
    pl = np.zeros((4, 5, 3), np.float32)
    ctx = SegmentContext(SegmenterConfig(), pl, pixel_angle_rad=1e-3)
    later = ctx.with_levels(-1.3, 1.4)
    assert (later.floor_z_m, later.ceiling_z_m) == (-1.3, 1.4)
    assert ctx.floor_z_m is None and later.points_level is pl and later.pixel_angle_rad == 1e-3



def test_the_context_s_pixels_with_depth_are_every_coordinate_finite_and_read_only():
    """``valid``: a pixel has depth when all three coordinates are finite (a NaN or inf in any
    one of them drops it), as ``np.isfinite(points).all(axis=-1)`` says; one array per
    context, which no step may change."""
    from sim2radar.reconstruct.backproject import finite_rows

    rng = np.random.default_rng(3)
    pl = rng.normal(size=(6, 7, 3)).astype(np.float32)
    for k, bad in enumerate((np.nan, np.inf, -np.inf)):
        pl[rng.random((6, 7)) < 0.2, k] = bad
    ctx = SegmentContext(SegmenterConfig(), pl)
    assert np.array_equal(ctx.valid, np.isfinite(pl).all(axis=-1)) and ctx.valid is ctx.valid
    assert 0 < ctx.valid.sum() < 42
    with pytest.raises(ValueError, match="read-only"):
        ctx.valid[0, 0] = True
    for n in (1, 2, 4):                               # any short last axis, and flat rows
        a = rng.normal(size=(50, n))
        a[rng.random((50, n)) < 0.1] = np.nan
        assert np.array_equal(finite_rows(a), np.isfinite(a).all(axis=-1))


def _key(seg):
    return (seg.segment_id.tobytes(), seg.labels, seg.scores.tobytes(),
            seg.door_boxes_level.tobytes(), sorted(seg.info.items()))


def test_one_segmenter_shared_between_threads_gives_the_sequential_results():
    """Frames of two sizes (two pixel angles) segmented by one instance on four threads at once
    give, bit for bit, what each gives alone; the instance holds its config and nothing of a
    call (the per-call state lives in a context that ends with the call)."""
    frames = [corridor_frame(*size, seed=s) for size, s in (((256, 192), 1), ((160, 120), 3))]
    inputs = [(FrameInput(f.rgb, f.intrinsics), DepthResult(f.depth_m)) for f in frames]
    backend = BuiltinSegments()
    alone = [_key(segment_frame(fi, d, SegmenterConfig())) for fi, d in inputs]
    with ThreadPoolExecutor(4) as pool:
        shared = list(pool.map(lambda i: _key(backend.segment(*inputs[i % 2])), range(8)))
    assert shared == [alone[i % 2] for i in range(8)]
    assert set(vars(backend)) == {"config"}
