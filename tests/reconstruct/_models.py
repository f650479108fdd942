"""Test fixtures for the production reconstruction backends (helper E1).

* An analytic corridor scene (axis-aligned planes + one cabinet box) ray-cast from the camera:
  RGB, exact z-depth, face ids, and a 16-beam-like LiDAR scan — the ground truth for the depth
  backends.
* Tiny torch models exported to ONNX with the public input/output signatures of MoGe-2, SAM2
  (encoder + decoder) and Grounding DINO, producing known outputs, so the backends' loading,
  pre- and post-processing are tested without any real weights.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim2radar.camera import CameraIntrinsics

# ---------------------------------------------------------------------------------------------
# Analytic corridor
# ---------------------------------------------------------------------------------------------

#: Corridor interior [m] in the camera frame (x right, y down, z forward); camera at the origin.
CORRIDOR_LO = np.array([-1.2, -1.3, -1.0])
CORRIDOR_HI = np.array([1.0, 1.5, 14.0])
#: A cabinet standing against the left wall [m].
CABINET_LO = np.array([-1.2, 0.3, 3.0])
CABINET_HI = np.array([-0.6, 1.5, 4.0])

# face ids: 0..5 corridor (-x wall, +x wall, ceiling, floor, back, end wall), 6..11 cabinet faces
FACE_COLOURS = np.array(
    [
        [200, 190, 170], [185, 175, 160], [240, 240, 235], [110, 110, 120], [90, 90, 90],
        [150, 160, 200],
        [60, 90, 140], [70, 100, 150], [50, 80, 130], [55, 85, 135], [65, 95, 145],
        [45, 75, 125],
    ],
    dtype=np.float64,
)


def _raycast(dirs: np.ndarray, with_cabinet: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Ray parameter t (distance along unit-less dir) and face id for rays from the origin."""
    d = np.where(np.abs(dirs) < 1e-12, 1e-12, dirs)
    # Exit of the corridor box (we are inside it).
    t_lo = CORRIDOR_LO / d
    t_hi = CORRIDOR_HI / d
    t_far = np.maximum(t_lo, t_hi)
    axis = np.argmin(t_far, axis=1)
    t = t_far[np.arange(len(d)), axis]
    positive_side = t_hi[np.arange(len(d)), axis] >= t_lo[np.arange(len(d)), axis]
    face = 2 * axis + positive_side.astype(int)
    if with_cabinet:
        c_lo = CABINET_LO / d
        c_hi = CABINET_HI / d
        t_near = np.minimum(c_lo, c_hi)
        t_out = np.maximum(c_lo, c_hi).min(axis=1)
        t_in = t_near.max(axis=1)
        hit = (t_in <= t_out) & (t_in > 0) & (t_in < t)
        c_axis = np.argmax(t_near, axis=1)
        c_pos = c_hi[np.arange(len(d)), c_axis] < c_lo[np.arange(len(d)), c_axis]
        t = np.where(hit, t_in, t)
        face = np.where(hit, 6 + 2 * c_axis + c_pos.astype(int), face)
    return t, face


def corridor_intrinsics(width: int = 96, height: int = 72, hfov_deg: float = 70.0):
    return CameraIntrinsics.from_fov(width, height, hfov_deg)


def render_corridor(k: CameraIntrinsics, with_cabinet: bool = True, noise: float = 2.0, seed=0):
    """RGB (H, W, 3) uint8, z-depth (H, W) float32 [m], face id (H, W) int of the corridor."""
    u = np.arange(k.width) + 0.5
    v = np.arange(k.height) + 0.5
    uu, vv = np.meshgrid(u, v)
    dirs = np.stack([(uu - k.cx) / k.fx, (vv - k.cy) / k.fy, np.ones_like(uu)], -1).reshape(-1, 3)
    t, face = _raycast(dirs, with_cabinet)
    depth = (t * dirs[:, 2]).reshape(k.height, k.width).astype(np.float32)
    face = face.reshape(k.height, k.width)
    rng = np.random.default_rng(seed)
    rgb = FACE_COLOURS[face] + rng.normal(0, noise, (k.height, k.width, 3))
    return np.clip(rgb, 0, 255).astype(np.uint8), depth, face


def lidar_scan(
    n_beams: int = 16,
    elev_deg: tuple[float, float] = (-30.0, 30.0),
    az_step_deg: float = 0.4,
    az_half_deg: float = 60.0,
    with_cabinet: bool = True,
) -> np.ndarray:
    """A 16-beam-like spinning LiDAR at the camera origin: (N, 3) float32 points [m]."""
    el = np.radians(np.linspace(elev_deg[0], elev_deg[1], n_beams))
    az = np.radians(np.arange(-az_half_deg, az_half_deg + 1e-9, az_step_deg))
    ee, aa = np.meshgrid(el, az, indexing="ij")
    dirs = np.stack(
        [np.cos(ee) * np.sin(aa), -np.sin(ee), np.cos(ee) * np.cos(aa)], -1
    ).reshape(-1, 3)
    t, _ = _raycast(dirs, with_cabinet)
    return (dirs * t[:, None]).astype(np.float32)


# ---------------------------------------------------------------------------------------------
# Tiny ONNX models
# ---------------------------------------------------------------------------------------------


def export_moge_like(
    path: Path,
    *,
    plane: tuple[float, float, float],
    ref_intrinsics: CameraIntrinsics,
    scale: float,
    shift: float,
    reported_metric_scale: float | None = None,
    output_names: tuple[str, ...] = ("points", "normal", "mask", "metric_scale"),
    input_names: tuple[str, ...] = ("image", "num_tokens"),
) -> Path:
    """Export a tiny model with MoGe-2's ONNX signature whose output is a known affine point map.

    The true scene is the plane ``1/Z = a x_n + b y_n + c`` seen by a camera with
    ``ref_intrinsics`` (``x_n = (u - cx) / fx``, ``y_n = (v - cy) / fy`` at pixel centres; the
    model rescales the intrinsics to the H, W it is fed). MoGe's convention is
    ``P_metric = (points + (0, 0, shift)) * metric_scale``, so the model outputs
    ``points = P_true / scale - (0, 0, shift)``, ``mask`` = 1, ``normal`` = (0, 0, -1) and
    ``metric_scale = reported_metric_scale`` (default ``scale``: a perfect metric head).

    Inputs: ``image`` (B, 3, H, W) float32 in [0, 1], ``num_tokens`` int64 scalar.
    Outputs: ``points`` (B, H, W, 3), ``normal`` (B, H, W, 3), ``mask`` (B, H, W),
    ``metric_scale`` (B,).
    """
    import torch

    a, b, c = plane
    k = ref_intrinsics
    ms = scale if reported_metric_scale is None else reported_metric_scale

    class MoGeLike(torch.nn.Module):
        def forward(self, image, num_tokens):
            ones = torch.ones_like(image[0, 0])  # (H, W), keeps H and W dynamic in the graph
            u = ones.cumsum(1) - 0.5
            v = ones.cumsum(0) - 0.5
            sx = ones.sum(1)[0] / k.width
            sy = ones.sum(0)[0] / k.height
            xn = (u - k.cx * sx) / (k.fx * sx)
            yn = (v - k.cy * sy) / (k.fy * sy)
            z = 1.0 / (a * xn + b * yn + c)
            p = torch.stack([xn * z, yn * z, z - shift * scale], -1) / scale
            p = p[None] * torch.ones_like(image[:, :1, :1, :1]).permute(0, 2, 3, 1)
            mask = (image.mean(1) >= -1.0).to(torch.float32)
            normal = torch.zeros_like(p) + torch.tensor([0.0, 0.0, -1.0])
            msc = torch.ones_like(image[:, 0, 0, 0]) * ms + num_tokens.to(torch.float32) * 0.0
            return p, normal, mask, msc

    dummy = (torch.rand(1, 3, 24, 32), torch.tensor(1800, dtype=torch.int64))
    _export(MoGeLike().eval(), dummy, path, input_names, output_names,
            {input_names[0]: {0: "batch", 2: "height", 3: "width"}})
    return path


def _export(model, dummy, path, input_names, output_names, dynamic_axes=None) -> None:
    """torch.onnx.export with the TorchScript exporter, quietly."""
    import warnings

    import torch

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            model,
            dummy,
            str(path),
            input_names=list(input_names),
            output_names=list(output_names),
            dynamic_axes=dynamic_axes,
            opset_version=17,
            dynamo=False,
        )
