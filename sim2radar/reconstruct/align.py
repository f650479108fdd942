"""Scale-and-shift alignment of monocular depth to sparse LiDAR depth (paper §3 Stage 1, eq. 1).

The paper grounds monocular depth in metric units with

    s*, t* = argmin_{s,t} sum_i (s * d_mono(p_i) + t - d_lidar(p_i))^2          (paper eq. 1)

over the pixels p_i that carry a LiDAR return. Plain least squares is what eq. (1) writes, but a
real LiDAR-to-camera projection always contains gross outliers: returns from behind a thin object
that the camera does not see (parallax between the two sensors), glass and mirror multipath, and
mixed pixels at depth edges. One such point at 10 m where the mono depth says 2 m moves the
least-squares line a lot. :func:`align_scale_shift` therefore solves eq. (1) robustly:

1. RANSAC over minimal two-point samples (Fischler & Bolles 1981) with an inlier band that grows
   with depth (LiDAR range noise is roughly proportional to range),
2. then iteratively re-weighted least squares with Huber weights (Huber 1964; Holland & Welsch
   1977) on the RANSAC inliers, the scale of the residuals from the median absolute deviation.

``method="lsq"`` gives plain eq. (1) for comparison.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np

__all__ = ["ScaleShift", "align_scale_shift", "fit_scale_shift"]

#: MAD -> standard deviation of a normal distribution.
_MAD_TO_SIGMA = 1.4826


@dataclasses.dataclass(frozen=True)
class ScaleShift:
    """Result of a scale-and-shift fit ``d_metric = scale * d_mono + shift``.

    Attributes
    ----------
    scale : float [m per mono unit]
    shift_m : float [m]
    n_points : int — LiDAR pixels used as input.
    n_inliers : int — pixels kept by the robust fit (all of them for ``lsq``).
    rms_m : float [m] — RMS residual over the inliers.
    method : str
    """

    scale: float
    shift_m: float
    n_points: int
    n_inliers: int
    rms_m: float
    method: str

    def apply(self, depth_mono: np.ndarray) -> np.ndarray:
        """``scale * depth_mono + shift_m`` as float32 (no masking)."""
        return (self.scale * np.asarray(depth_mono, np.float64) + self.shift_m).astype(np.float32)


def _lsq(x: np.ndarray, y: np.ndarray, w: np.ndarray | None = None) -> tuple[float, float]:
    """Weighted least squares for y ≈ s x + t (paper eq. 1 with weights)."""
    if w is None:
        w = np.ones_like(x)
    sw = w.sum()
    if sw <= 0:
        raise ValueError("all weights are zero")
    mx = (w * x).sum() / sw
    my = (w * y).sum() / sw
    vx = (w * (x - mx) ** 2).sum()
    if vx <= 1e-12 * max(1.0, sw * mx * mx):
        # Degenerate (all mono depths equal): only a shift is identifiable; keep the scale at 1.
        return 1.0, float(my - mx)
    s = (w * (x - mx) * (y - my)).sum() / vx
    return float(s), float(my - s * mx)


def fit_scale_shift(
    mono_depth: np.ndarray,
    lidar_depth: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    method: Literal["robust", "lsq"] = "robust",
    inlier_rel: float = 0.05,
    inlier_abs_m: float = 0.05,
    ransac_iters: int = 200,
    huber_k: float = 1.345,
    irls_iters: int = 10,
    min_points: int = 3,
    seed: int = 0,
) -> ScaleShift:
    """Fit ``lidar ≈ scale * mono + shift`` (paper eq. 1), robust to outlier LiDAR points.

    Parameters
    ----------
    mono_depth : (H, W) or (N,) float — monocular (relative or metric) depth.
    lidar_depth : same shape, float [m] — sparse LiDAR depth; 0 / NaN where there is no return.
    mask : same shape, bool, optional — pixels to use; default: lidar > 0 and both finite.
    method : ``"robust"`` (RANSAC + Huber IRLS) or ``"lsq"`` (plain eq. 1).
    inlier_rel, inlier_abs_m : RANSAC inlier band |residual| < inlier_abs_m + inlier_rel * d_lidar.
    ransac_iters : number of two-point samples.
    huber_k : Huber threshold in units of the robust residual sigma.
    irls_iters : IRLS iterations after RANSAC.
    min_points : fewer usable points raise ``ValueError``.
    seed : RNG seed for RANSAC (the result is deterministic for a given seed).
    """
    mono = np.asarray(mono_depth, dtype=np.float64)
    lidar = np.asarray(lidar_depth, dtype=np.float64)
    if mono.shape != lidar.shape:
        raise ValueError(f"mono_depth {mono.shape} and lidar_depth {lidar.shape} differ in shape")
    valid = np.isfinite(mono) & np.isfinite(lidar) & (lidar > 0)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != mono.shape:
            raise ValueError(f"mask {mask.shape} does not match depth shape {mono.shape}")
        valid &= mask
    x = mono[valid]
    y = lidar[valid]
    n = x.size
    if n < max(min_points, 2):
        raise ValueError(
            f"scale/shift alignment needs at least {max(min_points, 2)} pixels with both a mono "
            f"depth and a LiDAR depth, got {n}; check that the LiDAR points project into the image"
        )
    if method == "lsq":
        s, t = _lsq(x, y)
        r = s * x + t - y
        return ScaleShift(s, t, n, n, float(np.sqrt(np.mean(r**2))), "lsq")
    if method != "robust":
        raise ValueError(f"method must be 'robust' or 'lsq', got {method!r}")

    band = inlier_abs_m + inlier_rel * y
    rng = np.random.default_rng(seed)
    best_inliers = None
    best_count = -1
    best_cost = np.inf
    pairs = rng.integers(0, n, size=(ransac_iters, 2))
    for i, j in pairs:
        dx = x[i] - x[j]
        if abs(dx) < 1e-9 * max(1.0, abs(x[i])):
            continue
        s = (y[i] - y[j]) / dx
        if s <= 0:  # depth must grow with depth
            continue
        t = y[i] - s * x[i]
        r = np.abs(s * x + t - y)
        inl = r < band
        count = int(inl.sum())
        cost = float(np.minimum(r / band, 1.0).sum())  # MSAC cost breaks ties
        if count > best_count or (count == best_count and cost < best_cost):
            best_inliers, best_count, best_cost = inl, count, cost
    if best_inliers is None or best_count < 2:
        best_inliers = np.ones(n, dtype=bool)

    # Least squares on the RANSAC inliers, then Huber IRLS over all points starting from there;
    # the Huber weights down-weight the outliers and the final inlier set is recomputed.
    s, t = _lsq(x[best_inliers], y[best_inliers])
    for _ in range(irls_iters):
        r = s * x + t - y
        sigma = _MAD_TO_SIGMA * np.median(np.abs(r[best_inliers] - np.median(r[best_inliers])))
        sigma = max(sigma, 1e-6)
        a = np.abs(r) / (huber_k * sigma)
        w = np.where(a <= 1.0, 1.0, 1.0 / np.maximum(a, 1e-12))
        w[~best_inliers] = 0.0  # RANSAC outliers stay out
        s_new, t_new = _lsq(x, y, w)
        best_inliers = np.abs(s_new * x + t_new - y) < band
        if best_inliers.sum() < 2:
            break
        converged = abs(s_new - s) < 1e-9 * abs(s) + 1e-12 and abs(t_new - t) < 1e-9
        s, t = s_new, t_new
        if converged:
            break
    r = s * x + t - y
    inl = np.abs(r) < band
    rms = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else float("nan")
    return ScaleShift(float(s), float(t), n, int(inl.sum()), rms, "robust")


def align_scale_shift(
    mono_depth: np.ndarray,
    lidar_depth_sparse: np.ndarray,
    mask: np.ndarray | None = None,
    **kwargs,
) -> tuple[float, float]:
    """Robust solution ``(s, t)`` of paper eq. (1); see :func:`fit_scale_shift` for options.

    Returns
    -------
    s : float — scale; t : float [m] — shift, so that ``s * mono_depth + t`` is metric depth.
    """
    fit = fit_scale_shift(mono_depth, lidar_depth_sparse, mask, **kwargs)
    return fit.scale, fit.shift_m
