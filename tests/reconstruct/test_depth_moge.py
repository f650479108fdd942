"""Tests for the ``moge`` depth backend with a tiny test-built ONNX model of MoGe-2's signature."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct._onnx import ModelSignatureError
from sim2radar.reconstruct.depth_moge import MogeDepth, recover_focal_shift, recover_shift
from sim2radar.reconstruct.types import DEPTH_BACKENDS, FrameInput, ReconstructionInputError
from tests.reconstruct._models import export_moge_like

#: A tilted plane 1/Z = a x_n + b y_n + c: floor-like, depth 2..6 m over the image.
PLANE = (0.03, 0.12, 0.25)
K = CameraIntrinsics(fx=40.0, fy=40.0, cx=24.0, cy=18.0, width=48, height=36)
SCALE, SHIFT = 2.0, 0.7  # the model outputs P_true / SCALE - (0, 0, SHIFT)


def _truth(k: CameraIntrinsics) -> np.ndarray:
    u = (np.arange(k.width) + 0.5 - k.cx) / k.fx
    v = (np.arange(k.height) + 0.5 - k.cy) / k.fy
    return 1.0 / (PLANE[0] * u[None, :] + PLANE[1] * v[:, None] + PLANE[2])


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    d = tmp_path_factory.mktemp("moge")
    good = export_moge_like(d / "moge.onnx", plane=PLANE, ref_intrinsics=K, scale=SCALE,
                            shift=SHIFT)
    off = export_moge_like(d / "moge_off.onnx", plane=PLANE, ref_intrinsics=K, scale=SCALE,
                           shift=SHIFT, reported_metric_scale=0.8 * SCALE)
    renamed = export_moge_like(d / "moge_bad.onnx", plane=PLANE, ref_intrinsics=K, scale=SCALE,
                               shift=SHIFT, output_names=("pts", "normal", "mask", "metric_scale"))
    return {"good": good, "off": off, "renamed": renamed}


def _rgb(k):
    return np.full((k.height, k.width, 3), 128, np.uint8)


def test_registered():
    assert DEPTH_BACKENDS.get("moge") is MogeDepth


def test_metric_depth_with_known_intrinsics(models):
    res = MogeDepth(model_path=str(models["good"])).estimate(FrameInput(_rgb(K), K))
    gt = _truth(K)
    assert res.info["shift"] == pytest.approx(SHIFT, abs=1e-3)
    assert res.info["metric_scale"] == pytest.approx(SCALE)
    assert (res.depth_m > 0).all()
    assert np.max(np.abs(res.depth_m - gt) / gt) < 1e-3


def test_focal_and_shift_recovered_without_intrinsics(models):
    res = MogeDepth(model_path=str(models["good"]), recover_focal=True).estimate(
        FrameInput(_rgb(K), K)
    )
    assert res.info["fx_px"] == pytest.approx(K.fx, rel=0.01)
    assert res.info["shift"] == pytest.approx(SHIFT, rel=0.01)
    gt = _truth(K)
    v = res.depth_m > 0
    assert v.mean() > 0.9
    assert np.mean(np.abs(res.depth_m[v] - gt[v]) / gt[v]) < 0.01


def test_inference_resolution_and_reprojection(models):
    # Inference at 32 px long side, depth returned at the frame's 48 x 36 grid.
    res = MogeDepth(model_path=str(models["good"]), input_max_side=32).estimate(
        FrameInput(_rgb(K), K)
    )
    gt = _truth(K)
    v = res.depth_m > 0
    assert res.depth_m.shape == gt.shape and v.mean() > 0.95
    assert np.mean(np.abs(res.depth_m[v] - gt[v]) / gt[v]) < 0.01


def test_wrong_metric_scale_is_fixed_by_lidar_alignment(models):
    gt = _truth(K)
    rng = np.random.default_rng(0)
    rows, cols = rng.integers(0, K.height, 150), rng.integers(0, K.width, 150)
    z = gt[rows, cols]
    pts = np.stack([(cols + 0.5 - K.cx) / K.fx * z, (rows + 0.5 - K.cy) / K.fy * z, z], 1)
    pts[:30, :] *= 1.8  # 20 % gross outliers along the ray (behind the plane)
    frame = FrameInput(_rgb(K), K, pts.astype(np.float32))
    unaligned = MogeDepth(model_path=str(models["off"]), align_to_lidar=False).estimate(frame)
    assert np.median(unaligned.depth_m / gt) == pytest.approx(0.8, abs=0.01)
    res = MogeDepth(model_path=str(models["off"])).estimate(frame)
    assert res.info["alignment"]["scale"] == pytest.approx(1.25, rel=0.01)
    assert np.mean(np.abs(res.depth_m - gt) / gt) < 0.01


def test_post_processing_functions_directly():
    gt = _truth(K)
    u = (np.arange(K.width) + 0.5 - K.cx) / K.fx
    v = (np.arange(K.height) + 0.5 - K.cy) / K.fy
    p = np.stack([u[None, :] * gt, v[:, None] * gt, gt], -1) / 3.0
    p[..., 2] -= 0.25
    valid = np.ones(gt.shape, bool)
    assert recover_shift(p, valid, K) == pytest.approx(0.25, abs=1e-4)
    f, t = recover_focal_shift(p, valid)
    assert f * np.hypot(K.width, K.height) / 2 == pytest.approx(K.fx, rel=1e-3)
    assert t == pytest.approx(0.25, abs=1e-3)


def test_missing_and_mismatched_models_fail_clearly(models, tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        MogeDepth(model_path=str(tmp_path / "nope.onnx"))
    with pytest.raises(ModelSignatureError, match="missing outputs.*points"):
        MogeDepth(model_path=str(models["renamed"]))
    # ... but configurable names make the same file usable.
    ok = MogeDepth(model_path=str(models["renamed"]),
                   output_names=("pts", "normal", "mask", "metric_scale"))
    assert ok.estimate(FrameInput(_rgb(K), K)).depth_m.max() > 0
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(ModelSignatureError, match="cannot load"):
        MogeDepth(model_path=str(junk))
    with pytest.raises(ValueError, match="known options"):
        MogeDepth(model_path=str(models["good"]), tokens=5)


def test_no_metric_head_and_no_lidar_is_an_error(tmp_path):
    p = export_moge_like(tmp_path / "m1.onnx", plane=PLANE, ref_intrinsics=K, scale=SCALE,
                         shift=SHIFT, output_names=("points", "normal", "mask", "scale_unused"))
    with pytest.raises(ReconstructionInputError, match="no metric scale"):
        MogeDepth(model_path=str(p)).estimate(FrameInput(_rgb(K), K))
    rel = MogeDepth(model_path=str(p), require_metric=False).estimate(FrameInput(_rgb(K), K))
    assert rel.info["metric"] is False
