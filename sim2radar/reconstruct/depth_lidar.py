"""Stage 1 ``lidar`` backend: dense metric depth from sparse LiDAR, guided by the RGB image.

Method — first-order, edge-aware normalized convolution of inverse depth:

* The LiDAR points (camera frame, OpenCV axes) are projected with the pinhole model and
  z-buffered into a sparse depth image (:func:`project_lidar`).
* For a plane, inverse depth ``1/z`` is an affine function of the pixel coordinates
  (``n · X = d`` with ``X = z K^-1 [u v 1]^T`` gives ``1/z = n · K^-1 [u v 1]^T / d``), so a local
  *affine* model of inverse depth is exact on every planar surface (floors, walls, ceilings, doors)
  and only the edges between surfaces need care.
* At every pixel we fit ``1/z(u, v) ≈ c0 + c1 (u - u0) + c2 (v - v0)`` to the LiDAR samples by
  weighted least squares — first-order normalized convolution (Knutsson & Westin, "Normalized and
  differential convolution", CVPR 1993, eqs. 7–9) — where the applicability (the weights) is the
  edge-aware fast global smoother of the RGB image (Min et al., "Fast Global Image Smoothing Based
  on Weighted Least Squares", IEEE TIP 2014; ``cv2.ximgproc.fastGlobalSmootherFilter``). All nine
  weighted moments are smoothed sparse images, so the whole completion is nine O(HW) filter passes
  and one batched 3×3 solve. Colour edges stop the weights, so depth does not bleed from a door
  into the wall behind it.
* The fit runs at a few kernel widths (``n_scales``; fine widths keep creases and edges sharp,
  coarse ones extend planes into the bands above and below a LiDAR's vertical field of view),
  plus, with ``fill_holes``, one colour-blind pass at the coarsest width. Each pixel takes the
  candidate with the smallest *expected relative error* ``E = (r + noise) * sqrt(g)``: ``r`` is the
  weighted RMS residual of the local affine fit relative to the fitted inverse depth (how planar
  the support is), ``noise`` the LiDAR's relative range noise (``lidar_noise_rel``), ``g`` the
  leverage of the pixel in its own fit (1 at the centroid of the support, growing with the
  squared distance when it is extrapolated; regression prediction variance). Candidates with a
  sample density below ``min_density`` (relative to the median at the samples) do not count.
* Pixels whose best ``E`` exceeds ``max_expected_error`` are holes: depth 0, never a guess.
  Confidence = density × (1 − E / max_expected_error), in [0, 1].
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from sim2radar.camera import CameraIntrinsics, project
from sim2radar.reconstruct.backproject import (
    FloorPlane,
    extend_to_floor,
    find_floor,
    gravity_up,
    points_from_depth,
    surface_normals,
)
from sim2radar.reconstruct.types import (
    DEPTH_BACKENDS,
    DepthResult,
    FrameInput,
    ReconstructionInputError,
)

__all__ = ["LidarDepth", "LidarDepthConfig", "complete_depth", "project_lidar"]

log = logging.getLogger(__name__)


def project_lidar(
    points_cam: np.ndarray, intrinsics: CameraIntrinsics, *, min_depth_m: float = 0.05
) -> np.ndarray:
    """Z-buffer sparse LiDAR points into a depth image.

    Parameters
    ----------
    points_cam : (N, 3) float — points in the camera frame (x right, y down, z forward) [m].
    intrinsics : CameraIntrinsics
    min_depth_m : float [m] — points closer than this are dropped.

    Returns
    -------
    (H, W) float32 — z-depth [m] of the nearest point per pixel, 0 where no point falls.
    """
    pts = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(pts).all():
        bad = int((~np.isfinite(pts)).any(axis=1).sum())
        raise ReconstructionInputError(
            f"LiDAR points contain NaN/inf in {bad} rows; drop them before projection"
        )
    uv, valid = project(pts, intrinsics)
    valid &= pts[:, 2] >= min_depth_m
    h, w = intrinsics.height, intrinsics.width
    depth = np.zeros((h, w), dtype=np.float32)
    if not valid.any():
        return depth
    col = np.floor(uv[valid, 0]).astype(np.int64)
    row = np.floor(uv[valid, 1]).astype(np.int64)
    z = pts[valid, 2]
    # z-buffer: write far points first so the nearest one per pixel wins.
    order = np.argsort(-z, kind="stable")
    depth[row[order], col[order]] = z[order]
    return depth


@dataclasses.dataclass(frozen=True)
class LidarDepthConfig:
    """Options of the ``lidar`` depth backend.

    Attributes
    ----------
    min_points : int — fewer LiDAR points in view raise an error.
    lambda_ : float or None — fast-global-smoother strength of the finest width; None picks it
        from the sample spacing ((2 × the median pixel distance to the nearest sample)^2).
    n_scales, scale_factor : widths ``lambda_ * scale_factor**k`` for k < n_scales.
    sigma_color : float — colour sensitivity of the guide on 0..255 intensities (smaller = edges
        stop the weights more).
    gradient_prior_px : float [px] — ridge on the affine slopes; where the samples spread less
        than this the fit falls back to a constant (zero-order normalized convolution).
    lidar_noise_rel : float — relative LiDAR range noise used in the expected error.
    max_expected_error : float — pixels with a larger expected relative error are holes.
    min_density : float — candidates with less relative sample density are ignored.
    fill_holes : bool — add a colour-blind candidate at the coarsest width.
    min_depth_m, max_depth_m : float [m] — valid depth range of the output.
    floor_fill : bool — below each column's lowest measured pixel, continue the surface seen
        there down to the floor and then the floor (``backproject.extend_to_floor``), with the
        floor plane from the LiDAR returns or, where none lie on it, from the rig calibration
        the frame carries (``FrameInput.camera_height_m``, with ``up_cam``).
    """

    min_points: int = 20
    lambda_: float | None = None
    n_scales: int = 4
    scale_factor: float = 4.0
    sigma_color: float = 8.0
    gradient_prior_px: float = 0.25
    lidar_noise_rel: float = 0.01
    max_expected_error: float = 0.3
    min_density: float = 0.02
    fill_holes: bool = True
    min_depth_m: float = 0.05
    max_depth_m: float = 100.0
    floor_fill: bool = True

    def __post_init__(self) -> None:
        if self.min_points < 3:
            raise ValueError(f"lidar depth: min_points must be >= 3, got {self.min_points}")
        if self.lambda_ is not None and self.lambda_ <= 0:
            raise ValueError(f"lidar depth: lambda_ must be > 0, got {self.lambda_}")
        if self.n_scales < 1 or self.scale_factor <= 1:
            raise ValueError("lidar depth: need n_scales >= 1 and scale_factor > 1")
        if self.sigma_color <= 0:
            raise ValueError(f"lidar depth: sigma_color must be > 0, got {self.sigma_color}")
        if not 0 <= self.min_density < 1:
            raise ValueError(
                f"lidar depth: min_density must lie in [0, 1), got {self.min_density}"
            )
        if self.max_expected_error <= 0 or self.lidar_noise_rel < 0:
            raise ValueError("lidar depth: need max_expected_error > 0 and lidar_noise_rel >= 0")
        if not 0 < self.min_depth_m < self.max_depth_m:
            raise ValueError("lidar depth: need 0 < min_depth_m < max_depth_m")


def _auto_lambda(mask: np.ndarray) -> float:
    import cv2

    dist = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
    gap = float(np.median(dist))
    return float(np.clip((2.0 * max(gap, 1.0)) ** 2, 4.0, 1e5))


def _first_order_nc(
    guide: np.ndarray,
    inv: np.ndarray,
    mask: np.ndarray,
    lam: float,
    sigma_color: float,
    ridge_px: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Edge-aware first-order normalized convolution (Knutsson & Westin 1993, eqs. 7-9).

    Returns the fitted inverse depth (H, W), the applicability density S(mask) (H, W) and the
    weighted RMS residual of the local affine fit relative to the fitted inverse depth (H, W).
    """
    import cv2

    h, w = inv.shape
    scale = float(max(h, w))
    # Centred, normalised coordinates keep the float32 moment images well conditioned.
    u = ((np.arange(w, dtype=np.float32) + 0.5 - w / 2) / scale)[None, :].repeat(h, 0)
    v = ((np.arange(h, dtype=np.float32) + 0.5 - h / 2) / scale)[:, None].repeat(w, 1)
    m = mask.astype(np.float32)
    y = np.where(mask, inv, 0).astype(np.float32)
    fgs = cv2.ximgproc.createFastGlobalSmootherFilter(guide, float(lam), float(sigma_color))
    s = {}
    for name, img in (
        ("1", m), ("u", m * u), ("v", m * v), ("uu", m * u * u), ("uv", m * u * v),
        ("vv", m * v * v), ("y", m * y), ("yu", m * y * u), ("yv", m * y * v),
        ("yy", m * y * y),
    ):
        s[name] = fgs.filter(np.ascontiguousarray(img)).astype(np.float64)
    s1 = np.maximum(s["1"], 0.0)
    u0 = u.astype(np.float64)
    v0 = v.astype(np.float64)
    # Moments about the pixel itself: a = u - u0, b = v - v0.
    sa = s["u"] - u0 * s1
    sb = s["v"] - v0 * s1
    saa = s["uu"] - 2 * u0 * s["u"] + u0 * u0 * s1
    sbb = s["vv"] - 2 * v0 * s["v"] + v0 * v0 * s1
    sab = s["uv"] - u0 * s["v"] - v0 * s["u"] + u0 * v0 * s1
    sya = s["yu"] - u0 * s["y"]
    syb = s["yv"] - v0 * s["y"]
    ridge = (ridge_px / scale) ** 2 * s1
    # Closed-form inverse of the symmetric 3x3 normal matrix A = [[a, b, c], [b, d, e], [c, e, f]]
    # (adjugate / determinant), vectorised over pixels.
    a, b, c, d, e, f = s1, sa, sb, saa + ridge, sab, sbb + ridge
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    good = (s1 > 1e-9 * max(float(s1.max()), 1e-30)) & (det > 0)
    det = np.where(good, det, 1.0)
    y0, y1, y2 = s["y"], sya, syb
    coef0 = (c00 * y0 + c01 * y1 + c02 * y2) / det
    coef1 = (c01 * y0 + c11 * y1 + c12 * y2) / det
    coef2 = (c02 * y0 + c12 * y1 + c22 * y2) / det
    # Weighted mean squared residual of the affine fit, sum w (y - c.phi)^2 / sum w
    #   = (S(m y^2) - c.b) / S(m) since A c = b — how planar the support is.
    res = (s["yy"] - (coef0 * y0 + coef1 * y1 + coef2 * y2)) / np.where(good, s1, 1.0)
    rel_rms = np.sqrt(np.maximum(res, 0.0)) / np.maximum(np.abs(coef0), 1e-12)
    # Leverage of the pixel in its own fit, S(m) (A^-1)_00: 1 at the centroid of the support,
    # growing with the squared distance / spread when the pixel is extrapolated (the prediction
    # variance sigma^2 x0^T (X^T W X)^-1 x0 of weighted least squares, in units of sigma^2 / S(m)).
    leverage = np.maximum(c00 / det * s1, 1.0)
    inv_fit = np.where(good, coef0, 0.0)
    rel_rms = np.where(good, rel_rms, np.inf)
    return (inv_fit.astype(np.float32), s1.astype(np.float32), rel_rms.astype(np.float32),
            leverage.astype(np.float32))


def complete_depth(
    rgb: np.ndarray,
    sparse_depth_m: np.ndarray,
    config: LidarDepthConfig | None = None,
) -> tuple[np.ndarray, np.ndarray, dict]:
    """Densify a sparse depth image with the RGB image as guide (see module docstring).

    Parameters
    ----------
    rgb : (H, W, 3) uint8 — guide image.
    sparse_depth_m : (H, W) float [m] — sparse z-depth, 0 where there is no sample.
    config : LidarDepthConfig

    Returns
    -------
    depth_m : (H, W) float32 [m] — dense z-depth, 0 in holes.
    confidence : (H, W) float32 in [0, 1].
    info : dict — ``lambda``, ``n_samples``, ``hole_fraction``, ``pixels_per_candidate``.
    """
    cfg = config or LidarDepthConfig()
    sparse = np.asarray(sparse_depth_m, dtype=np.float32)
    if sparse.shape != rgb.shape[:2]:
        raise ReconstructionInputError(
            f"sparse depth {sparse.shape} does not match the image {rgb.shape[:2]}"
        )
    mask = np.isfinite(sparse) & (sparse > 0)
    n = int(mask.sum())
    if n < cfg.min_points:
        raise ReconstructionInputError(
            f"only {n} LiDAR pixels in view, need at least {cfg.min_points} "
            "(lidar depth option min_points); check the LiDAR-to-camera extrinsics"
        )
    inv = np.zeros_like(sparse)
    inv[mask] = 1.0 / sparse[mask]
    lam0 = cfg.lambda_ if cfg.lambda_ is not None else _auto_lambda(mask)
    guide = np.ascontiguousarray(rgb, dtype=np.uint8)

    cands = [(guide, lam0 * cfg.scale_factor**k) for k in range(cfg.n_scales)]
    if cfg.fill_holes:
        cands.append((np.zeros_like(guide), cands[-1][1]))  # colour-blind: plain WLS smoothing
    best_e = np.full(sparse.shape, np.inf, np.float32)
    inv_out = np.zeros(sparse.shape, np.float32)
    dens_out = np.zeros(sparse.shape, np.float32)
    choice = np.full(sparse.shape, -1, np.int8)
    for k, (g, lam) in enumerate(cands):
        inv_k, dens_k, rel_k, lev_k = _first_order_nc(g, inv, mask, lam, cfg.sigma_color,
                                                      cfg.gradient_prior_px)
        density = np.clip(dens_k / max(float(np.median(dens_k[mask])), 1e-12), 0.0, 1.0)
        err = (rel_k + cfg.lidar_noise_rel) * np.sqrt(lev_k)
        better = (density >= cfg.min_density) & (inv_k > 0) & np.isfinite(err) & (err < best_e)
        best_e = np.where(better, err, best_e)
        inv_out = np.where(better, inv_k, inv_out)
        dens_out = np.where(better, density, dens_out)
        choice = np.where(better, k, choice)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(inv_out > 0, 1.0 / inv_out, 0.0).astype(np.float32)
    ok = (
        np.isfinite(depth)
        & (best_e <= cfg.max_expected_error)
        & (depth >= cfg.min_depth_m)
        & (depth <= cfg.max_depth_m)
    )
    conf = dens_out * np.clip(1.0 - best_e / cfg.max_expected_error, 0.0, 1.0)
    depth = np.where(ok, depth, 0.0).astype(np.float32)
    conf = np.where(ok, conf, 0.0).astype(np.float32)
    info = {
        "lambda": float(lam0),
        "n_samples": n,
        "hole_fraction": float(1.0 - ok.mean()),
        "pixels_per_candidate": [int(((choice == k) & ok).sum()) for k in range(len(cands))],
    }
    return depth, conf, info


#: Confidence given to pixels whose depth comes from the floor plane / surface extension.
FLOOR_FILL_CONFIDENCE = 0.3


@DEPTH_BACKENDS.register("lidar")
class LidarDepth:
    """Stage 1 backend ``lidar``: RGB-guided completion of the frame's sparse LiDAR.

    Options are the fields of :class:`LidarDepthConfig` (keyword arguments). ``estimate`` returns
    a :class:`DepthResult` whose ``info`` holds JSON-able values: ``n_lidar_points`` (LiDAR
    pixels in the image), ``hole_fraction``, ``pixels_per_candidate``, ``confidence_mean``, the
    filter strength ``lambda`` and, with ``floor_fill``, ``up_cam`` (gravity up, camera frame),
    ``floor`` (``FloorPlane.to_info()`` or None; the builtin segmenter takes its up and floor
    from these two) and ``floor_filled_fraction``.
    The result's ``confidence`` is the per-pixel confidence map ((H, W) float32 in [0, 1], 0 in
    holes, ``FLOOR_FILL_CONFIDENCE`` where the floor fill set the depth). The backend keeps no
    per-call state, so one instance serves many threads.
    """

    def __init__(self, **options) -> None:
        try:
            self.config = LidarDepthConfig(**options)
        except TypeError as exc:
            known = ", ".join(f.name for f in dataclasses.fields(LidarDepthConfig))
            raise ValueError(f"lidar depth backend: {exc}; known options: {known}") from None

    def _floor(self, frame: FrameInput, depth_m: np.ndarray
               ) -> tuple[np.ndarray | None, FloorPlane | None]:
        """Gravity up — the frame's calibrated ``up_cam``, else from the completed depth's
        normals checked against the image's vertical lines — and the floor plane
        (``backproject.find_floor``); (None, None) without depth."""
        k = frame.intrinsics
        points = points_from_depth(depth_m, k)
        if np.isfinite(points).all(axis=-1).sum() < 16:
            return None, None
        normals = surface_normals(points)
        up = gravity_up(normals, frame.rgb, k, frame.up_cam)
        return up, find_floor(normals, up, k, frame.lidar_points, frame.camera_height_m)

    def estimate(self, frame: FrameInput) -> DepthResult:
        if frame.lidar_points is None:
            raise ReconstructionInputError(
                f"{frame.name}: the 'lidar' depth backend needs lidar_points (N, 3) in the camera "
                "frame; pass --lidar points.npy or choose the 'moge' depth backend"
            )
        pts = frame.lidar_points
        if len(pts) < self.config.min_points:
            raise ReconstructionInputError(
                f"{frame.name}: {len(pts)} LiDAR points, need at least {self.config.min_points}"
            )
        sparse = project_lidar(pts, frame.intrinsics, min_depth_m=self.config.min_depth_m)
        n_view = int((sparse > 0).sum())
        if n_view == 0:
            raise ReconstructionInputError(
                f"{frame.name}: none of the {len(pts)} LiDAR points falls inside the image; "
                "are they in the camera frame (x right, y down, z forward)?"
            )
        try:
            depth, conf, info = complete_depth(frame.rgb, sparse, self.config)
        except ReconstructionInputError as exc:
            raise ReconstructionInputError(f"{frame.name}: {exc}") from None
        if self.config.floor_fill:
            up, floor = self._floor(frame, depth)
            if up is not None:  # the segmenter takes this search's up and floor
                info["up_cam"] = [float(x) for x in up]
            info["floor"] = None if floor is None else floor.to_info()
            filled = np.zeros(depth.shape, bool)
            if floor is not None:
                depth, filled = extend_to_floor(depth, frame.intrinsics, floor)
                depth = np.where((depth >= self.config.min_depth_m)
                                 & (depth <= self.config.max_depth_m), depth, 0).astype(np.float32)
                conf = np.where(filled & (depth > 0), FLOOR_FILL_CONFIDENCE, conf)
            info["floor_filled_fraction"] = float((filled & (depth > 0)).mean())
            info["hole_fraction"] = float((depth <= 0).mean())
        log.debug("%s: lidar completion %s", frame.name, info)
        valid = depth > 0
        info["confidence_mean"] = float(conf[valid].mean()) if valid.any() else 0.0
        return DepthResult(
            depth_m=depth, info={"backend": "lidar", "n_lidar_points": n_view, **info},
            confidence=conf)
