"""Stage 1 ``moge`` backend: MoGe-2 monocular geometry via onnxruntime (paper §3 Stage 1).

The user supplies an ONNX export of MoGe-2 (Wang et al., "MoGe: Unlocking Accurate Monocular
Geometry Estimation", CVPR 2025; MoGe-2 adds the metric-scale head) with the public signature

=========== ======================= =========================================================
name        shape / dtype           meaning
=========== ======================= =========================================================
image       (B, 3, H, W) float32    RGB in [0, 1] (no mean/std normalisation; inside the graph)
num_tokens  () int64                ViT token budget (MoGe's resolution level; 1200..3600)
points      (B, H, W, 3) float32    affine-invariant point map (x right, y down, z forward)
normal      (B, H, W, 3) float32    surface normals (unused here)
mask        (B, H, W) float32/bool  validity (sky / undefined geometry = 0)
metric_scale (B,) float32           the metric scale of the point map
=========== ======================= =========================================================

Names are configurable (``input_names``, ``output_names``). What is *not* in the graph is done
here and tested:

1. **Shift (and focal) recovery.** MoGe's points are defined up to ``P = s·(x, y, z + t)``. With
   known intrinsics only the shift ``t`` is unknown: it is the value for which the points project
   onto their own pixel rays, ``x/(z+t) = (u - cx)/fx`` and ``y/(z+t) = (v - cy)/fy``
   (MoGe's ``solve_optimal_shift``). We solve the cross-multiplied linear least squares
   ``x - r_u (z + t) = 0`` in closed form and refine the reprojection residual with Gauss–Newton
   (``scipy.optimize.least_squares``). Without intrinsics (``recover_focal=True``) the focal ``f``
   (in half-diagonal units, principal point at the image centre, MoGe's convention) and ``t`` are
   found the same way (MoGe's ``recover_focal_shift``): linear LS in (f, t), then refinement.
2. **Metric depth** ``z_m = (z + t) · metric_scale``.
3. **Optional LiDAR alignment**: when the frame has LiDAR, ``s, t`` of paper eq. (1) are fitted
   robustly (:mod:`sim2radar.reconstruct.align`) between this depth and the projected LiDAR.
4. **Reprojection to the frame's intrinsics**: the depth at the model's resolution and recovered
   intrinsics is inverse-warped onto the frame's pixel grid (same optical centre and axis, so the
   z-depth along a ray is unchanged); pixels whose ray leaves the model's view or crosses the
   validity mask are 0.
"""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np

from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct._onnx import OnnxModel
from sim2radar.reconstruct.align import fit_scale_shift
from sim2radar.reconstruct.depth_lidar import project_lidar
from sim2radar.reconstruct.types import (
    DEPTH_BACKENDS,
    DepthResult,
    FrameInput,
    ReconstructionInputError,
)

__all__ = [
    "MogeConfig",
    "MogeDepth",
    "recover_shift",
    "recover_focal_shift",
    "reproject_depth",
]

log = logging.getLogger(__name__)

#: (H, W) [px] of the synthetic frame :meth:`MogeDepth.check` runs.
CHECK_HW = (72, 96)


def _subsample(points: np.ndarray, valid: np.ndarray, rays: np.ndarray, max_n: int, seed: int = 0):
    idx = np.flatnonzero(valid.reshape(-1))
    if idx.size > max_n:
        idx = np.random.default_rng(seed).choice(idx, max_n, replace=False)
    return points.reshape(-1, 3)[idx].astype(np.float64), rays.reshape(-1, 2)[idx]


def recover_shift(
    points: np.ndarray, valid: np.ndarray, intrinsics: CameraIntrinsics, max_points: int = 4096
) -> float:
    """z-shift ``t`` that makes an affine point map project onto its pixels under known intrinsics.

    Parameters
    ----------
    points : (H, W, 3) float — affine-invariant point map at the resolution of ``intrinsics``.
    valid : (H, W) bool
    intrinsics : CameraIntrinsics of the point map's pixel grid.

    Returns
    -------
    t : float — in the point map's units; ``z + t`` is proportional to metric depth.
    """
    from scipy.optimize import least_squares

    h, w = valid.shape
    u = (np.arange(w) + 0.5 - intrinsics.cx) / intrinsics.fx
    v = (np.arange(h) + 0.5 - intrinsics.cy) / intrinsics.fy
    rays = np.stack(np.meshgrid(u, v), -1)  # (H, W, 2)
    p, r = _subsample(points, valid, rays, max_points)
    if len(p) < 3:
        raise ReconstructionInputError("MoGe: fewer than 3 valid points to recover the shift")
    # Linear LS of x - r_u (z + t) = 0, y - r_v (z + t) = 0 in t.
    num = ((p[:, 0] - r[:, 0] * p[:, 2]) * r[:, 0] + (p[:, 1] - r[:, 1] * p[:, 2]) * r[:, 1]).sum()
    den = (r**2).sum()
    t0 = num / den if den > 0 else 0.0
    lo = -p[:, 2].min() + 1e-6  # keep every point in front of the camera

    def resid(t):
        zz = p[:, 2] + t[0]
        return np.concatenate([p[:, 0] / zz - r[:, 0], p[:, 1] / zz - r[:, 1]])

    t0 = max(t0, lo + 1e-6)
    sol = least_squares(resid, [t0], bounds=([lo], [np.inf]), method="trf", x_scale="jac")
    return float(sol.x[0])


def recover_focal_shift(
    points: np.ndarray, valid: np.ndarray, max_points: int = 4096
) -> tuple[float, float]:
    """Focal and z-shift of an affine point map with unknown intrinsics (MoGe's convention).

    The principal point is the image centre; the focal ``f`` is in units of half the image
    diagonal, i.e. ``fx_px = fy_px = f * sqrt(W^2 + H^2) / 2``.

    Returns
    -------
    f : float (half-diagonal units); t : float — z-shift in the point map's units.
    """
    from scipy.optimize import least_squares

    h, w = valid.shape
    half_diag = math.hypot(w, h) / 2
    u = (np.arange(w) + 0.5 - w / 2) / half_diag
    v = (np.arange(h) + 0.5 - h / 2) / half_diag
    uv = np.stack(np.meshgrid(u, v), -1)
    p, r = _subsample(points, valid, uv, max_points)
    if len(p) < 3:
        raise ReconstructionInputError("MoGe: fewer than 3 valid points to recover focal/shift")
    # Linear LS of f x - u (z + t) = 0 in (f, t): [x, -u] [f, t]^T = u z.
    a = np.concatenate([np.stack([p[:, 0], -r[:, 0]], 1), np.stack([p[:, 1], -r[:, 1]], 1)])
    b = np.concatenate([r[:, 0] * p[:, 2], r[:, 1] * p[:, 2]])
    (f0, t0), *_ = np.linalg.lstsq(a, b, rcond=None)
    lo = -p[:, 2].min() + 1e-6

    def focal_for(t):
        xy = p[:, :2] / (p[:, 2:3] + t)
        return float((xy * r).sum() / max((xy * xy).sum(), 1e-30))

    def resid(t):
        xy = p[:, :2] / (p[:, 2:3] + t[0])
        return (focal_for(t[0]) * xy - r).reshape(-1)

    sol = least_squares(resid, [max(t0, lo + 1e-6)], bounds=([lo], [np.inf]), x_scale="jac")
    t = float(sol.x[0])
    f = focal_for(t)
    if not np.isfinite(f) or f <= 0:
        raise ReconstructionInputError(f"MoGe: recovered focal {f} is not positive; bad point map")
    return f, t


def reproject_depth(
    depth_src: np.ndarray,
    k_src: CameraIntrinsics,
    k_dst: CameraIntrinsics,
    valid_src: np.ndarray | None = None,
) -> np.ndarray:
    """Inverse-warp a z-depth image between two pinhole cameras sharing centre and axes.

    For each destination pixel the ray ``K_dst^-1 [u v 1]`` is looked up in the source image
    (``K_src`` times the ray); z-depth along a ray is the same in both cameras.

    Returns
    -------
    (H_dst, W_dst) float32 [m] — 0 outside the source view or where any interpolation neighbour
    is invalid.
    """
    import cv2

    src = np.asarray(depth_src, np.float32)
    valid = (src > 0) & np.isfinite(src) if valid_src is None else (valid_src & (src > 0))
    u = np.arange(k_dst.width, dtype=np.float64) + 0.5
    v = np.arange(k_dst.height, dtype=np.float64) + 0.5
    xn = (u - k_dst.cx) / k_dst.fx
    yn = (v - k_dst.cy) / k_dst.fy
    map_x = (k_src.fx * xn + k_src.cx - 0.5)[None, :].repeat(k_dst.height, 0).astype(np.float32)
    map_y = (k_src.fy * yn + k_src.cy - 0.5)[:, None].repeat(k_dst.width, 1).astype(np.float32)
    depth = cv2.remap(np.where(valid, src, 0).astype(np.float32), map_x, map_y, cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    vmask = cv2.remap(valid.astype(np.float32), map_x, map_y, cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    # Edge pixels whose centre maps within half a pixel outside the source grid are clamped.
    near = cv2.remap(np.where(valid, src, 0).astype(np.float32), map_x, map_y, cv2.INTER_NEAREST,
                     borderMode=cv2.BORDER_REPLICATE)
    inside = (map_x >= -0.5) & (map_x <= src.shape[1] - 0.5) & (map_y >= -0.5) & (
        map_y <= src.shape[0] - 0.5)
    edge = inside & (vmask < 0.999) & (near > 0)
    out = np.where(vmask >= 0.999, depth / np.maximum(vmask, 1e-6), 0.0)
    out = np.where(edge & (vmask > 0.0), near, out)
    return out.astype(np.float32)


@dataclasses.dataclass(frozen=True)
class MogeConfig:
    """Options of the ``moge`` depth backend.

    Attributes
    ----------
    model_path : str — the MoGe-2 ``.onnx`` (required).
    num_tokens : int — token budget fed to the graph (MoGe-2 uses 1200..3600; more = finer).
    input_max_side : int or None [px] — resize the image so its longer side is this before
        inference (None: native resolution). The intrinsics are scaled accordingly.
    recover_focal : bool — ignore the frame's intrinsics when recovering the shift and recover the
        focal too (use when the intrinsics are unreliable); the depth is then reprojected into the
        frame's intrinsics.
    align_to_lidar : bool — if the frame has LiDAR, robustly fit paper eq. (1) to it.
    require_metric : bool — without a ``metric_scale`` output and without LiDAR, raise (True) or
        return relative depth with ``info['metric'] = False`` (False).
    mask_threshold : float — ``mask`` values above this are valid.
    input_names : (image, num_tokens); output_names : (points, normal, mask, metric_scale).
    providers : onnxruntime providers (default CUDA if available, then CPU).
    """

    model_path: str
    num_tokens: int = 2500
    input_max_side: int | None = None
    recover_focal: bool = False
    align_to_lidar: bool = True
    require_metric: bool = True
    mask_threshold: float = 0.5
    input_names: tuple[str, str] = ("image", "num_tokens")
    output_names: tuple[str, str, str, str] = ("points", "normal", "mask", "metric_scale")
    providers: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        if not 1 <= int(self.num_tokens) <= 100_000:
            raise ValueError(f"moge: num_tokens must be a positive int, got {self.num_tokens}")
        if self.input_max_side is not None and self.input_max_side < 16:
            raise ValueError(f"moge: input_max_side must be >= 16 px, got {self.input_max_side}")
        object.__setattr__(self, "input_names", tuple(self.input_names))
        object.__setattr__(self, "output_names", tuple(self.output_names))
        if len(self.input_names) != 2 or len(self.output_names) != 4:
            raise ValueError("moge: input_names needs 2 names and output_names 4 names")


@DEPTH_BACKENDS.register("moge")
class MogeDepth:
    """Stage 1 backend ``moge`` (see the module docstring for the ONNX signature and the method).

    ``DepthResult.info`` holds ``shift``, ``metric_scale``, ``fx_px`` (recovered or given, at the
    frame's resolution), ``alignment`` (scale/shift/inliers when aligned to LiDAR), ``metric``,
    ``model_sha256``.
    """

    def __init__(self, **options) -> None:
        try:
            self.config = MogeConfig(**options)
        except TypeError as exc:
            known = ", ".join(f.name for f in dataclasses.fields(MogeConfig))
            raise ValueError(f"moge depth backend: {exc}; known options: {known}") from None
        c = self.config
        image_name, tokens_name = c.input_names
        self.model = OnnxModel(
            c.model_path,
            "MoGe-2 (depth backend 'moge', option model_path)",
            inputs=[image_name],
            optional_inputs=[tokens_name],
            outputs=[c.output_names[0], c.output_names[2]],
            providers=c.providers,
        )
        self.has_metric = c.output_names[3] in self.model.output_names

    def _infer(self, rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, float | None]:
        c = self.config
        image_name, tokens_name = c.input_names
        pts_name, _, mask_name, scale_name = c.output_names
        x = (rgb.astype(np.float32) / 255.0).transpose(2, 0, 1)[None]
        feeds = {image_name: np.ascontiguousarray(x)}
        if self.model.has_input(tokens_name):
            feeds[tokens_name] = np.array(int(c.num_tokens), dtype=np.int64)
        outs = [pts_name, mask_name] + ([scale_name] if self.has_metric else [])
        res = self.model.run(feeds, outs)
        pts = np.asarray(res[pts_name])
        h, w = rgb.shape[:2]
        if pts.shape != (1, h, w, 3):
            raise ReconstructionInputError(
                f"MoGe: output {pts_name!r} has shape {pts.shape}, expected (1, {h}, {w}, 3)"
            )
        mask = np.asarray(res[mask_name]).reshape(1, h, w)[0].astype(np.float32)
        scale = float(np.asarray(res[scale_name]).reshape(-1)[0]) if self.has_metric else None
        return pts[0].astype(np.float64), mask > c.mask_threshold, scale

    def check(self) -> str:
        """Run one small synthetic frame (:data:`CHECK_HW`, a vertical brightness ramp, 60° HFOV)
        through the graph and the post-processing; a one-line summary (``sim2radar models
        check``). Raises what :meth:`estimate` raises."""
        import time

        h, w = CHECK_HW
        ramp = np.linspace(40, 220, h, dtype=np.float32)[:, None, None]
        rgb = np.broadcast_to(ramp, (h, w, 3)).astype(np.uint8)
        t0 = time.perf_counter()
        res = self.estimate(FrameInput(rgb, CameraIntrinsics.from_fov(w, h, 60.0),
                                       name="models-check"))
        d = res.depth_m[res.depth_m > 0]
        kind = "metric" if res.info.get("metric") else "relative"
        span = f"{d.min():.2f}-{d.max():.2f} m" if d.size else "no valid pixel"
        return (f"{self.model.path.name} ran a {w}x{h} image in {time.perf_counter() - t0:.2f} s: "
                f"{kind} depth {span} on {d.size / res.depth_m.size:.0%} of the pixels")

    def estimate(self, frame: FrameInput) -> DepthResult:
        import cv2

        c = self.config
        k = frame.intrinsics
        rgb = frame.rgb
        h0, w0 = frame.shape
        if c.input_max_side and max(h0, w0) != c.input_max_side:
            f = c.input_max_side / max(h0, w0)
            wi, hi = max(1, round(w0 * f)), max(1, round(h0 * f))
            rgb = cv2.resize(rgb, (wi, hi), interpolation=cv2.INTER_AREA)
        hi, wi = rgb.shape[:2]
        k_model_given = CameraIntrinsics(k.fx * wi / w0, k.fy * hi / h0, k.cx * wi / w0,
                                         k.cy * hi / h0, wi, hi)
        pts, valid, metric_scale = self._infer(rgb)
        valid &= np.isfinite(pts).all(-1)
        if valid.sum() < 3:
            raise ReconstructionInputError(f"{frame.name}: MoGe returned no valid pixels")
        if c.recover_focal:
            f_half, shift = recover_focal_shift(pts, valid)
            fpx = f_half * math.hypot(wi, hi) / 2
            k_model = CameraIntrinsics(fpx, fpx, wi / 2, hi / 2, wi, hi)
        else:
            shift = recover_shift(pts, valid, k_model_given)
            k_model = k_model_given
        z = pts[..., 2] + shift
        valid &= z > 0
        info: dict = {
            "backend": "moge",
            "shift": shift,
            "metric_scale": metric_scale,
            "fx_px": k_model.fx * w0 / wi,
            "fy_px": k_model.fy * h0 / hi,
            "model_sha256": self.model.sha256,
        }
        depth_model = np.where(valid, z * (metric_scale if metric_scale else 1.0), 0.0)
        depth = reproject_depth(depth_model, k_model, k, valid)
        metric = metric_scale is not None
        if c.align_to_lidar and frame.lidar_points is not None:
            sparse = project_lidar(frame.lidar_points, k)
            ok = depth > 0
            try:
                fit = fit_scale_shift(depth, sparse, ok)
            except ValueError as exc:
                raise ReconstructionInputError(f"{frame.name}: LiDAR alignment: {exc}") from None
            depth = np.where(ok, fit.apply(depth), 0.0).astype(np.float32)
            depth[depth <= 0] = 0.0
            info["alignment"] = dataclasses.asdict(fit)
            metric = True
        if not metric and c.require_metric:
            raise ReconstructionInputError(
                f"{frame.name}: the MoGe model has no {c.output_names[3]!r} output (MoGe-1?) and "
                "the frame has no LiDAR, so depth has no metric scale; supply LiDAR or set "
                "require_metric: false to accept relative depth"
            )
        info["metric"] = metric
        return DepthResult(depth_m=depth.astype(np.float32), info=info)
