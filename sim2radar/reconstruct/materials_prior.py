"""Stage 3 ``prior`` backend: semantic prior × colour/texture evidence, no learned weights.

Each segment starts from a material distribution for its semantic label (building practice:
fire-corridor doors are mostly metal, corridor floors tile or concrete, walls plasterboard or
concrete, windows glass, handrails and extinguishers metal — :data:`PRIORS`). Appearance
features measured on the segment's pixels then multiply the prior by likelihood ratios
(:data:`RULES`), and the posterior's arg-max is the label:

* wood: hue 15–45°, saturation 0.3–0.8, and an oriented grain (structure-tensor coherence);
* joint lines measured in metres on the surface (walls, floors, ceilings with depth; see
  :func:`surface_structure`): concrete-block masonry shows bed joints every 0.2 m with head
  joints staggered course to course (running bond); poured concrete shows formwork panel joints
  0.6 / 1.2 m apart; ceramic tiles a regular grout grid (0.25–0.6 m); suspended ceilings a
  dense dark 0.6 m T-bar grid; plasterboard and vinyl are smooth; concrete slabs mottled;
* image-space fallbacks when the surface is too far or small to rectify: grout lines (pixels
  much darker than their neighbourhood), strong grey mottling (concrete);
* brushed metal: grey with strongly oriented streaks;
* plastic: saturated, untextured colour on clutter / floors;
* glass doors: a dim, strongly but unorientedly textured view through the pane.

The reason string lists the features and the rules that fired, so a wrong label can be traced.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from sim2radar.reconstruct.backproject import finite_rows, normals_from_points, points_from_depth
from sim2radar.reconstruct.types import (
    MATERIAL_BACKENDS,
    DepthResult,
    FrameInput,
    MaterialLabel,
    Segments,
)
from sim2radar.vocab import MATERIAL_CLASSES, SEMANTIC_CLASSES

__all__ = ["PRIORS", "RULES", "AppearanceFeatures", "SurfaceStructure", "segment_features",
           "surface_structure", "PriorMaterials"]

#: P(material | semantic label) — plausible building-practice priors for indoor corridors.
PRIORS: dict[str, dict[str, float]] = {
    "wall": {"plasterboard": 0.6, "concrete": 0.32, "ceramic_tile": 0.08},
    "floor": {"ceramic_tile": 0.5, "concrete": 0.35, "plastic": 0.15},
    "ceiling": {"plasterboard": 0.65, "concrete": 0.35},
    "door": {"metal": 0.65, "wood": 0.27, "glass": 0.08},
    "window": {"glass": 0.95, "metal": 0.05},
    "fire_extinguisher": {"metal": 1.0},
    "handrail": {"metal": 0.7, "wood": 0.2, "plastic": 0.1},
    "clutter": {"metal": 0.5, "wood": 0.3, "plastic": 0.2},
    "unknown": {"plasterboard": 0.4, "concrete": 0.3, "metal": 0.3},
}


@dataclasses.dataclass(frozen=True)
class AppearanceFeatures:
    """Colour and texture statistics of one segment.

    Attributes
    ----------
    hue_deg : float [deg] — circular mean hue (0 red, 30 orange/brown, 120 green, 240 blue).
    saturation, value : float — median HSV saturation and value in [0, 1].
    lf_contrast : float — robust std (1.4826·MAD) of the band-pass (σ 1–5 px) luminance over
        its local mean: texture contrast with the shading removed (mottling, speckle).
    grout_frac : float — fraction of pixels on thin dark lines (grout): > 25 % darker than the
        5×5 morphological closing of the image (black-hat), which broad shading does not reach.
    coherence : float — structure-tensor coherence of the band-passed luminance in [0, 1]
        (1 = all texture gradients in one direction: grain, brushing).
    n_px : int — pixels used.
    structure : SurfaceStructure, optional — joint-line structure in metres (walls, floors,
        ceilings with depth; ``None`` when not measured).
    """

    hue_deg: float
    saturation: float
    value: float
    lf_contrast: float
    grout_frac: float
    coherence: float
    n_px: int
    structure: SurfaceStructure | None = None


def _image_maps(rgb: np.ndarray) -> dict[str, np.ndarray]:
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV_FULL).astype(np.float32)
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float32) + 1.0
    b1 = cv2.GaussianBlur(gray, (0, 0), 1.0)
    b2 = cv2.GaussianBlur(gray, (0, 0), 5.0)
    band = (b1 - b2) / b2  # local texture contrast, shading (low frequencies) removed
    # thin dark lines (grout): morphological black-hat with a 5x5 element, relative depth
    closed = cv2.morphologyEx(gray, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
    gx = cv2.Sobel(band, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(band, cv2.CV_32F, 0, 1, ksize=3)
    return {
        "hue": hsv[..., 0] * (2 * np.pi / 256), "sat": hsv[..., 1] / 255, "val": hsv[..., 2] / 255,
        "band": band, "dark": (closed - gray) > 0.25 * closed,
        "jxx": gx * gx, "jyy": gy * gy, "jxy": gx * gy,
    }


def _features(maps: dict[str, np.ndarray], mask: np.ndarray) -> AppearanceFeatures:
    m = mask & np.isfinite(maps["band"])
    n = int(m.sum())
    if n == 0:
        return AppearanceFeatures(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0)
    # shrink the mask so that segment borders do not count as texture
    inner = cv2.erode(m.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    if inner.sum() >= 30:
        m = inner
    hue = maps["hue"][m]
    sat = maps["sat"][m]
    hue_deg = float(np.degrees(np.arctan2((np.sin(hue) * sat).mean(), (np.cos(hue) * sat).mean()))
                    % 360)
    jxx, jyy, jxy = maps["jxx"][m].sum(), maps["jyy"][m].sum(), maps["jxy"][m].sum()
    tr = jxx + jyy
    coherence = float(np.sqrt((jxx - jyy) ** 2 + 4 * jxy**2) / tr) if tr > 1e-6 else 0.0
    return AppearanceFeatures(
        hue_deg=hue_deg,
        saturation=float(np.median(sat)),
        value=float(np.median(maps["val"][m])),
        lf_contrast=float(1.4826 * np.median(np.abs(maps["band"][m] - np.median(maps["band"][m])))),
        grout_frac=float(maps["dark"][m].mean()),
        coherence=coherence,
        n_px=n,
    )


def segment_features(rgb: np.ndarray, mask: np.ndarray) -> AppearanceFeatures:
    """Appearance features of the pixels ``mask`` (H, W) bool of an (H, W, 3) uint8 image."""
    return _features(_image_maps(np.asarray(rgb, np.uint8)), np.asarray(mask, bool))


@dataclasses.dataclass(frozen=True)
class SurfaceStructure:
    """Joint-line structure of a planar segment, measured in metres on the rectified surface.

    The segment's pixels are intersected with its fitted plane (so per-pixel depth noise does
    not smear the pattern), expressed in in-plane axes (walls: along the wall and up) and binned
    into ``cell_m`` cells; only pixels whose footprint is at most one cell are used. The line
    map (thin dark lines: relative morphological black-hat) is then analysed per axis: the
    projection profile across the axis is autocorrelated and its strongest peak at a lag of
    0.1–1.3 m gives the spacing of the lines parallel to the axis.

    Attributes
    ----------
    period_h_m, score_h : float — spacing [m] (NaN if none) and normalised autocorrelation
        peak in [−1, 1] of lines parallel to the first axis (walls: horizontal lines — tile
        grout, block bed joints, formwork panel joints).
    period_v_m, score_v : float — the same for lines parallel to the second axis (walls:
        vertical lines).
    bond : float — running-bond score: correlation of the vertical-joint profiles of courses
        two apart minus that of adjacent courses (blocks in running bond ≈ 1, tile grids ≈ 0).
    line_frac : float — mean line strength over the rectified cells.
    mottling : float — robust relative std of the cells' luminance about its 0.2 m-scale local
        mean (albedo blotches of raw concrete; shading varies more slowly).
    extent_m : float — largest side of the rectified area [m].
    n_cells : int — cells with data (0 when the segment is not measurable).
    """

    period_h_m: float = float("nan")
    score_h: float = 0.0
    period_v_m: float = float("nan")
    score_v: float = 0.0
    bond: float = 0.0
    line_frac: float = 0.0
    mottling: float = 0.0
    extent_m: float = 0.0
    n_cells: int = 0

    def periodic(self, min_score: float = 0.25) -> tuple[bool, bool]:
        return self.score_h >= min_score, self.score_v >= min_score


#: Relative darkening below which a pixel is not on a line (denoised render noise ~1 %,
#: sensor noise ~1-2 %).
LINE_NOISE_FLOOR = 0.04


def _line_strength(rgb: np.ndarray) -> np.ndarray:
    """(H, W) float32 ≥ 0: relative darkening of each pixel below the 5×5 morphological
    closing around it (thin dark lines: joints, grout). :func:`surface_structure` turns it into
    a line strength in [0, 1] above a per-surface noise floor."""
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float32) + 1.0
    closed = cv2.morphologyEx(gray, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
    return (closed - gray) / closed


def _profile_period(coord: np.ndarray, value: np.ndarray, cell_m: float,
                    lags_m: tuple[float, float] = (0.17, 1.3)) -> tuple[float, float]:
    """Spacing [m] and normalised autocorrelation of a line-strength profile along ``coord``."""
    idx = np.floor((coord - coord.min()) / cell_m).astype(np.int64)
    n = int(idx.max()) + 1
    cnt = np.bincount(idx, minlength=n).astype(np.float64)
    tot = np.bincount(idx, value, minlength=n)
    ok = cnt > 0
    prof = np.where(ok, tot / np.maximum(cnt, 1), 0.0)
    w = ok.astype(np.float64)
    z = (prof - prof[ok].mean()) * w
    lo = max(int(round(lags_m[0] / cell_m)), 4)
    hi = min(int(round(lags_m[1] / cell_m)), n // 2)
    if hi <= lo + 2:
        return float("nan"), 0.0
    m = 1 << int(np.ceil(np.log2(2 * n)))
    fz, fw = np.fft.rfft(z, m), np.fft.rfft(w, m)
    num = np.fft.irfft(fz * np.conj(fz), m)[:n]
    den = np.fft.irfft(fw * np.conj(fw), m)[:n]
    with np.errstate(invalid="ignore", divide="ignore"):
        ac = num / np.maximum(den, 1.0)
    if ac[0] <= 1e-9:
        return float("nan"), 0.0
    ac = ac / ac[0]
    ac[den < 0.3 * den[0]] = -1.0  # too little overlap to trust
    seg = ac[lo:hi + 1]
    # local maxima only (a slowly decaying autocorrelation is not a period)
    peaks = [i for i in range(1, len(seg) - 1) if seg[i] >= seg[i - 1] and seg[i] >= seg[i + 1]]
    if not peaks:
        return float("nan"), 0.0
    top = max(seg[i] for i in peaks)
    if top <= 0:
        return float("nan"), 0.0
    # the fundamental: the shortest lag whose peak is nearly as strong as the strongest
    # (multiples of the spacing correlate as well)
    best = min(i for i in peaks if seg[i] >= 0.55 * top)
    return float((lo + best) * cell_m), float(seg[best])


def _bond(h: np.ndarray, v: np.ndarray, line: np.ndarray, period_m: float, cell_m: float) -> float:
    """Running-bond score of cells at (h along the courses, v across) with line strength."""
    if not np.isfinite(period_m):
        return 0.0
    # phase of the bed joints: where the folded profile peaks
    ph = (v % period_m)
    nb = max(int(round(period_m / cell_m)), 4)
    fold = np.bincount(np.minimum((ph / period_m * nb).astype(int), nb - 1), line, minlength=nb)
    phase = (np.argmax(fold) + 0.5) / nb * period_m
    rel = (v - phase) % period_m
    interior = (rel > 0.25 * period_m) & (rel < 0.75 * period_m)
    course = np.floor((v - phase) / period_m).astype(np.int64)
    hi = np.floor((h - h.min()) / cell_m).astype(np.int64)
    nh = int(hi.max()) + 1
    profiles = {}
    for c in np.unique(course[interior]):
        sel = interior & (course == c)
        if sel.sum() < 20:
            continue
        cnt = np.bincount(hi[sel], minlength=nh)
        tot = np.bincount(hi[sel], line[sel], minlength=nh)
        profiles[int(c)] = (np.where(cnt > 0, tot / np.maximum(cnt, 1), np.nan))

    def corr(lag):
        vals = []
        for c, pa in profiles.items():
            pb = profiles.get(c + lag)
            if pb is None:
                continue
            ok = np.isfinite(pa) & np.isfinite(pb)
            if ok.sum() < 10 or pa[ok].std() < 1e-6 or pb[ok].std() < 1e-6:
                continue
            vals.append(np.corrcoef(pa[ok], pb[ok])[0, 1])
        return float(np.mean(vals)) if vals else float("nan")

    c1, c2 = corr(1), corr(2)
    if not (np.isfinite(c1) and np.isfinite(c2)):
        return 0.0
    return c2 - c1


def _plane_masks(points_cam: np.ndarray, normals: np.ndarray, mask: np.ndarray,
                 max_planes: int = 3, min_px: int = 1500) -> list[np.ndarray]:
    """Split a segment into its largest planes (e.g. both walls of a corridor in one oracle
    instance): the most common normal direction, then the most common offset along it."""
    out = []
    rest = mask & finite_rows(normals) & finite_rows(points_cam)
    normals_0, points_0 = np.nan_to_num(normals), np.nan_to_num(points_cam)  # once, not per plane
    for _ in range(max_planes):
        if rest.sum() < min_px:
            break
        n = normals[rest].astype(np.float64)
        # the most common direction on a 7^3 lattice (unit normals x 3, rounded): one integer
        # per cell, in the lexicographic order of its (x, y, z), so a tie goes to the same
        # cell as np.unique(axis=0) + argmax would pick (a counting pass instead of a sort)
        q = np.round(n * 3).astype(np.int64) + 3
        cell = (q[:, 0] * 7 + q[:, 1]) * 7 + q[:, 2]
        n0 = n[cell == np.argmax(np.bincount(cell, minlength=343))].mean(axis=0)
        n0 /= np.linalg.norm(n0)
        cand = rest & (np.abs(normals_0 @ n0) > 0.95)
        d = points_0 @ n0
        hist_d = d[cand]
        if len(hist_d) < min_px:
            break
        bins = np.floor(hist_d / 0.05).astype(np.int64)
        low = bins.min()
        mode = (low + np.argmax(np.bincount(bins - low)) + 0.5) * 0.05  # the lowest of ties
        plane = cand & (np.abs(d - mode) < 0.1)
        if plane.sum() >= min_px:
            out.append(plane)
        rest = rest & ~plane & ~cand if plane.sum() < min_px else rest & ~plane
    return out


def surface_structure(line: np.ndarray, points_cam: np.ndarray, mask: np.ndarray, fx: float,
                      *, normals: np.ndarray | None = None, gray: np.ndarray | None = None,
                      vertical_plane: bool | None = None, cell_m: float | None = None,
                      max_cells: int = 300) -> SurfaceStructure:
    """Measure the joint-line structure of one segment (see :class:`SurfaceStructure`).

    With ``normals`` (H, W, 3) the segment is first split into its largest planes and the
    plane with the most measurable cells is reported; without, the segment is one plane.
    The mask is eroded by 3 px first: object borders (shadowed corners, door edges) are dark
    lines that belong to no surface texture.
    """
    eroded = cv2.erode(np.asarray(mask, np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    if eroded.sum() >= 300:
        mask = eroded
    if normals is None:
        return _plane_structure(line, points_cam, mask, fx, gray, vertical_plane, cell_m,
                                max_cells)
    best = SurfaceStructure()
    for plane in _plane_masks(points_cam, normals, mask):
        st = _plane_structure(line, points_cam, plane, fx, gray, vertical_plane, cell_m,
                              max_cells)
        if st.n_cells > best.n_cells:
            best = st
    return best


def _mottling(iu: np.ndarray, iv: np.ndarray, lum: np.ndarray, cell_m: float) -> float:
    """Robust relative std of cell luminance about its 0.2 m Gaussian local mean."""
    nu, nv = int(iu.max()) + 1, int(iv.max()) + 1
    g = np.zeros((nu, nv), np.float32)
    w = np.zeros((nu, nv), np.float32)
    np.add.at(g, (iu, iv), lum)
    np.add.at(w, (iu, iv), 1.0)
    sigma = 0.2 / cell_m
    gs = cv2.GaussianBlur(g, (0, 0), sigma)
    ws = cv2.GaussianBlur(w, (0, 0), sigma)
    ok = (w > 0) & (ws > 0.3)
    if ok.sum() < 100:
        return 0.0
    r = (g[ok] / w[ok]) / (gs[ok] / ws[ok]) - 1.0
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


def _plane_structure(line: np.ndarray, points_cam: np.ndarray, mask: np.ndarray, fx: float,
                     gray: np.ndarray | None = None, vertical_plane: bool | None = None,
                     cell_m: float | None = None, max_cells: int = 300) -> SurfaceStructure:
    """Measure the joint-line structure of one planar segment (see :class:`SurfaceStructure`).

    Parameters
    ----------
    line : (H, W) float — relative darkening below the local closing (:func:`_line_strength`).
    points_cam : (H, W, 3) float — camera-frame points [m], NaN where no depth.
    mask : (H, W) bool — the segment.
    fx : float [px] — focal length (pixel footprint = depth / fx / cos(incidence)).
    vertical_plane : bool, optional — walls: axes along the wall and up (searched within ±6°
        of the camera's up); otherwise (floors, ceilings) the in-plane angle is searched over
        0–180°. Default: decided from the plane normal.
    cell_m : float [m] — rectification cell size; default: the 30th percentile of the pixel
        footprints, within 1.5–3 cm.
    """
    m = mask & finite_rows(points_cam)
    ys, xs = np.nonzero(m)
    if len(ys) < 300:
        return SurfaceStructure()
    p = points_cam[ys, xs].astype(np.float64)
    sub = p[:: max(1, len(p) // 4000)]
    c = np.median(sub, axis=0)
    _, _, vt = np.linalg.svd(sub - c, full_matrices=False)
    nrm = vt[2]
    if abs(nrm @ c) < 1e-6:
        return SurfaceStructure()
    ray = p / np.linalg.norm(p, axis=1, keepdims=True)
    cos_i = np.abs(ray @ nrm)
    # intersect each pixel's ray with the plane: coordinates free of per-pixel depth noise
    t = (c @ nrm) / np.where(np.abs(ray @ nrm) > 1e-6, ray @ nrm, np.nan)
    q = ray * t[:, None]
    foot = q[:, 2] / fx / np.maximum(cos_i, 0.05)
    if cell_m is None:
        fin = foot[np.isfinite(foot) & (foot > 0)]
        cell_m = float(np.clip(np.percentile(fin, 30), 0.015, 0.03)) if len(fin) else 0.015
    keep = np.isfinite(t) & (t > 0) & (foot <= cell_m) & (np.abs((p - c) @ nrm) < 0.1)
    if keep.sum() < 300:
        return SurfaceStructure()
    q, val = q[keep] - c, line[ys[keep], xs[keep]].astype(np.float64)
    # line strength in [0, 1]: darkening above the noise floor of this surface (twice the
    # median darkening — joints are a minority of pixels — and at least LINE_NOISE_FLOOR),
    # full strength 25 % above it
    floor = max(LINE_NOISE_FLOOR, 2.0 * float(np.median(val)))
    val = np.clip((val - floor) / 0.25, 0.0, 1.0)
    lum = (gray[ys[keep], xs[keep]].astype(np.float64) if gray is not None
           else np.ones(len(val)))
    up_cam = np.array([0.0, -1.0, 0.0])
    if vertical_plane is None:
        vertical_plane = abs(nrm @ up_cam) < 0.5
    if vertical_plane:
        e2 = up_cam - (up_cam @ nrm) * nrm
        angles = np.radians(np.arange(-6.0, 6.5, 1.0))
    else:
        e2 = np.cross(nrm, [1.0, 0.0, 0.0])
        if np.linalg.norm(e2) < 0.3:
            e2 = np.cross(nrm, [0.0, 0.0, 1.0])
        angles = np.radians(np.arange(0.0, 180.0, 3.0))
    e2 /= np.linalg.norm(e2)
    e1 = np.cross(e2, nrm)
    u0, v0 = q @ e1, q @ e2
    # keep a window of max_cells around the median (nearest, finest part dominates anyway)
    half = max_cells * cell_m / 2
    win = (np.abs(u0 - np.median(u0)) < half) & (np.abs(v0 - np.median(v0)) < half)
    u0, v0, val, lum = u0[win], v0[win], val[win], lum[win]
    if len(val) < 300:
        return SurfaceStructure()
    # one sample per cell (mean), so near-range pixels do not outweigh the rest
    iu = np.floor((u0 - u0.min()) / cell_m).astype(np.int64)
    iv = np.floor((v0 - v0.min()) / cell_m).astype(np.int64)
    key = iu * (int(iv.max()) + 1) + iv
    uniq, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    cu = np.bincount(inv, u0) / cnt
    cv = np.bincount(inv, v0) / cnt
    cl = np.bincount(inv, val) / cnt
    if len(uniq) < 200:
        return SurfaceStructure()
    mott = _mottling(iu, iv, lum, cell_m) if gray is not None else 0.0
    best = None
    for a in angles:
        ca, sa = np.cos(a), np.sin(a)
        h = ca * cu + sa * cv      # along the first axis
        v = -sa * cu + ca * cv     # along the second axis
        pv, sv = _profile_period(v, cl, cell_m)  # lines parallel to the first axis
        ph, sh = _profile_period(h, cl, cell_m)  # lines parallel to the second axis
        score = max(sv, sh)
        if best is None or score > best[0]:
            best = (score, a, pv, sv, ph, sh, h, v)
    _, a, pv, sv, ph, sh, h, v = best
    if not vertical_plane and sh > sv:  # first axis: the one with the stronger lines
        pv, sv, ph, sh, h, v = ph, sh, pv, sv, v, h
    # running bond: head joints staggered across the bed joints (either axis may carry them)
    bond = max(_bond(h, v, cl, pv, cell_m) if sv >= 0.25 else 0.0,
               _bond(v, h, cl, ph, cell_m) if sh >= 0.25 else 0.0)
    extent = float(max(np.ptp(cu), np.ptp(cv)))
    return SurfaceStructure(period_h_m=pv, score_h=sv, period_v_m=ph, score_v=sh,
                            bond=float(bond), line_frac=float(cl.mean()), mottling=mott,
                            extent_m=extent, n_cells=len(uniq))


def _is_wood(f: AppearanceFeatures) -> bool:
    return 12 <= f.hue_deg <= 48 and 0.3 <= f.saturation <= 0.85 and 0.1 <= f.value <= 0.8


def _measured(f: AppearanceFeatures) -> bool:
    return f.structure is not None and f.structure.n_cells >= 300


def _score(f: AppearanceFeatures) -> float:
    return max(f.structure.score_h, f.structure.score_v)


def _within(p: float, lo: float, hi: float) -> bool:
    return bool(np.isfinite(p) and lo <= p <= hi)


def _lines(f: AppearanceFeatures, at_least: float) -> bool:
    return _measured(f) and f.structure.line_frac >= at_least


def _running_bond(f: AppearanceFeatures) -> bool:
    return _measured(f) and _score(f) >= 0.5 and f.structure.bond >= 0.3


def _block_courses(f: AppearanceFeatures) -> bool:
    """Horizontal bed joints every 0.2 m (concrete-block courses)."""
    st = f.structure
    return _lines(f, 0.01) and st.score_h >= 0.6 and _within(st.period_h_m, 0.17, 0.23)


def _formwork(f: AppearanceFeatures) -> bool:
    """Horizontal formwork panel joints 0.6 m (or 1.2 m) apart."""
    st = f.structure
    return (_lines(f, 0.01) and st.score_h >= 0.25 and st.bond < 0.3
            and (_within(st.period_h_m, 0.55, 0.72) or _within(st.period_h_m, 1.1, 1.3)))


#: Wall tile sizes [m] (procedural worlds 0.25–0.33 m; common wall tiles 0.2–0.4 m).
WALL_TILE_M = (0.24, 0.4)


def _tile_grid_wall(f: AppearanceFeatures) -> bool:
    """A grout grid of wall-tile spacing: strong lines in one direction, or a square grid — both
    directions at the same tile spacing, or one at it and the other at about twice it (the
    autocorrelation's fundamental lost to every other joint being fainter) — where each
    direction alone is faint. Concrete blocks have 0.2 m courses in running bond, formwork
    0.6 / 1.2 m panels: neither has a tile-sized period in both directions."""
    st = f.structure
    if not _lines(f, 0.02) or _running_bond(f) or _block_courses(f):
        return False
    ph, pv = st.period_h_m, st.period_v_m
    tile_h, tile_v = _within(ph, *WALL_TILE_M), _within(pv, *WALL_TILE_M)
    if (st.score_h >= 0.7 and tile_h) or (st.score_v >= 0.7 and tile_v):
        return True
    if tile_h and tile_v and abs(ph - pv) <= 0.15 * max(ph, pv) and min(st.score_h, st.score_v) >= 0.25:
        return True
    for p, s, q, t in ((ph, st.score_h, pv, st.score_v), (pv, st.score_v, ph, st.score_h)):
        if _within(p, *WALL_TILE_M) and s >= 0.55 and t >= 0.25 and _within(q, 1.8 * p, 2.4 * p):
            return True
    return False


def _ceiling_grid(f: AppearanceFeatures) -> bool:
    """Suspended ceiling: a square 0.6 m grid (both directions), or a dense dark T-bar grid
    where only one direction is resolved (grazing views)."""
    st = f.structure
    square = (st.score_h >= 0.5 and st.score_v >= 0.5 and _within(st.period_h_m, 0.55, 0.72)
              and _within(st.period_v_m, 0.55, 0.72))
    dense = (_lines(f, 0.08) and _score(f) >= 0.5
             and (_within(st.period_h_m, 0.55, 0.72) or _within(st.period_v_m, 0.55, 0.72)))
    return _lines(f, 0.01) and (square or dense)


def _soffit(f: AppearanceFeatures) -> bool:
    """Concrete slab soffit: joint lines / mottling, or formwork joints, but no ceiling grid."""
    return (not _ceiling_grid(f)
            and (_lines(f, 0.02) or (_formwork(f) and f.structure.score_h >= 0.5)))


def _pane(f: AppearanceFeatures) -> bool:
    """A glazed leaf shows the room behind it rather than a surface: darker than a lit leaf
    (median value < 0.15: the corridor's lights do not reach the room beyond) with strong
    texture of no dominant orientation (band-pass contrast > 0.15, coherence < 0.4: distant
    objects, and in path-traced renders the noise of that dim scene). Painted leaves are
    brighter (0.2–0.4 on the tuning worlds 3000–3029); a dark brushed-metal leaf has the same
    contrast but oriented streaks (coherence ≥ 0.77 there)."""
    return f.value < 0.15 and f.lf_contrast > 0.15 and f.coherence < 0.4


#: Line fraction of rectified floors: below FLOOR_SHEET_LINES a smooth sheet (vinyl), up to
#: FLOOR_TILE_LINES a mottled slab (raw concrete: 0.011–0.024 on the tuning worlds 3000–3009
#: with LiDAR depth completed to the floor, one of 16 up to 0.037), above it grout lines (tiles
#: ≥ 0.030 there) even where the grid itself is not resolved. A sheet threshold of 0.0098, which
#: separates the tuning worlds' vinyl (≤ 0.009) from their concrete, cost 3 points of material
#: accuracy on the held-out worlds 5000–5004: their concrete floors have fainter mottling.
FLOOR_SHEET_LINES = 0.004
FLOOR_TILE_LINES = 0.028


def _floor_grid(f: AppearanceFeatures) -> bool:
    """A regular grout grid on a floor (LiDAR-completed floor planes blur it: lenient). Raw
    concrete's mottling gives autocorrelation peaks up to ~0.53 on procedural-world floors,
    tile grids 0.55–0.95 (seeds 3000–3009)."""
    return _lines(f, 0.008) and _score(f) >= 0.55


def _floor_grout(f: AppearanceFeatures) -> bool:
    """Thin dark lines in the image on a floor: grout (poured concrete has none; > 3 % of the
    pixels on tiled floors, < 0.5 % on concrete and sheet floors)."""
    return f.grout_frac > 0.03 and not _is_wood(f)


#: (name, test, {material: likelihood ratio}, labels or None) — applied in order; each rule that
#: fires (and applies to the segment's label) multiplies. The joint-line rules use the
#: rectified :class:`SurfaceStructure` (walls, floors, ceilings; thresholds on the line
#: fraction separate joints from render/sensor noise, measured on procedural-world renders);
#: the image-space rules stand in when it could not be measured (too far, small, no depth).
RULES: tuple = (
    ("wood hue + grain", lambda f: _is_wood(f) and (f.coherence > 0.3 or f.lf_contrast > 0.05),
     {"wood": 8.0}, None),
    ("wood hue", lambda f: _is_wood(f) and f.coherence <= 0.3 and f.lf_contrast <= 0.05,
     {"wood": 3.0}, None),
    # walls
    ("running-bond joints (block masonry)", _running_bond,
     {"concrete": 10.0, "ceramic_tile": 0.3}, ("wall", "unknown")),
    ("0.2 m block courses", lambda f: _block_courses(f) and not _running_bond(f),
     {"concrete": 6.0, "ceramic_tile": 0.3}, ("wall", "unknown")),
    ("formwork panel joints", lambda f: _formwork(f) and not _block_courses(f)
     and not _tile_grid_wall(f), {"concrete": 5.0}, ("wall", "unknown")),
    ("tile grout grid", _tile_grid_wall, {"ceramic_tile": 8.0}, ("wall", "unknown")),
    ("irregular joint lines", lambda f: _lines(f, 0.02) and not (
        _running_bond(f) or _block_courses(f) or _formwork(f) or _tile_grid_wall(f)),
     {"concrete": 2.0}, ("wall", "unknown")),
    ("smooth paint, no joints", lambda f: _measured(f) and f.structure.line_frac < 0.01,
     {"plasterboard": 3.0, "concrete": 0.5, "ceramic_tile": 0.3}, ("wall", "unknown")),
    # floors
    ("floor grout grid", _floor_grid, {"ceramic_tile": 8.0}, ("floor",)),
    ("floor grout lines", lambda f: _measured(f) and not _floor_grid(f) and _floor_grout(f),
     {"ceramic_tile": 6.0}, ("floor",)),
    ("dense lines, grid unresolved", lambda f: _measured(f) and not _floor_grid(f)
     and not _floor_grout(f) and f.structure.line_frac >= FLOOR_TILE_LINES,
     {"ceramic_tile": 2.0}, ("floor",)),
    ("mottled slab, no grid", lambda f: _measured(f) and not _floor_grid(f)
     and not _floor_grout(f) and FLOOR_SHEET_LINES <= f.structure.line_frac < FLOOR_TILE_LINES,
     {"concrete": 4.0, "ceramic_tile": 0.3}, ("floor",)),
    ("smooth sheet floor, no grid", lambda f: _measured(f)
     and f.structure.line_frac < FLOOR_SHEET_LINES,
     {"plastic": 6.0, "ceramic_tile": 0.3}, ("floor",)),
    # ceilings
    ("suspended-ceiling grid", _ceiling_grid, {"plasterboard": 6.0, "concrete": 0.5},
     ("ceiling",)),
    ("concrete soffit (formwork joints, mottling)", lambda f: _soffit(f), {"concrete": 5.0},
     ("ceiling",)),
    ("smooth ceiling", lambda f: _measured(f) and f.structure.line_frac < 0.02
     and not _soffit(f), {"plasterboard": 2.0}, ("ceiling",)),
    # doors
    ("dim view through a pane", _pane, {"glass": 20.0}, ("door",)),
    # image-space fallbacks (no measurable structure)
    ("grout lines", lambda f: not _measured(f) and f.grout_frac > 0.03 and not _is_wood(f),
     {"ceramic_tile": 6.0}, None),
    # raw concrete (texture contrast 0.10-0.25); lighting and path-tracing noise alone reach
    # ~0.1 of band-pass contrast on plain walls, so only strong mottling counts
    ("grey mottling", lambda f: not _measured(f) and f.lf_contrast > 0.12 and f.saturation < 0.2
     and f.grout_frac < 0.03, {"concrete": 4.0}, None),
    ("smooth paint", lambda f: not _measured(f) and f.lf_contrast < 0.02 and f.grout_frac < 0.01,
     {"plasterboard": 1.5, "metal": 1.3}, None),
    ("brushed streaks", lambda f: f.coherence > 0.6 and f.saturation < 0.15
     and f.lf_contrast > 0.02, {"metal": 2.0}, None),
    ("saturated plain colour", lambda f: f.saturation > 0.45 and f.lf_contrast < 0.03
     and not _is_wood(f), {"plastic": 2.0}, None),
)

#: Labels whose segments get the rectified joint-line measurement.
STRUCTURE_LABELS = ("wall", "floor", "ceiling")


@MATERIAL_BACKENDS.register("prior")
class PriorMaterials:
    """Semantic prior × appearance rules (see the module docstring).

    Parameters
    ----------
    priors : dict, optional — ``{label: {material: probability}}`` overriding :data:`PRIORS`
        per label (each row must use ``vocab.MATERIAL_CLASSES`` names).
    use_rules : bool — False gives the prior's arg-max only.
    use_structure : bool — measure the rectified joint-line structure of wall / floor /
        ceiling segments from the depth (False: image-space rules only).
    """

    def __init__(self, priors: dict | None = None, *, use_rules: bool = True,
                 use_structure: bool = True) -> None:
        table = {k: dict(v) for k, v in PRIORS.items()}
        for label, row in (priors or {}).items():
            if label not in SEMANTIC_CLASSES:
                raise ValueError(f"prior materials: unknown label {label!r}; known: {SEMANTIC_CLASSES}")
            bad = sorted(set(row) - set(MATERIAL_CLASSES))
            if bad:
                raise ValueError(
                    f"prior materials: priors[{label!r}] has unknown material(s) {bad}; "
                    f"known: {MATERIAL_CLASSES}"
                )
            table[label] = {k: float(v) for k, v in row.items()}
        self.priors = table
        self.use_rules = bool(use_rules)
        self.use_structure = bool(use_structure)

    def posterior(self, label: str, features: AppearanceFeatures) -> tuple[dict[str, float], list[str]]:
        """Normalised material distribution for one segment and the names of the rules that fired."""
        post = dict(self.priors.get(label, self.priors["unknown"]))
        fired = []
        if self.use_rules:
            for name, test, ratios, labels in RULES:
                if labels is not None and label not in labels:
                    continue
                if test(features):
                    fired.append(name)
                    for mat, r in ratios.items():
                        if mat in post:
                            post[mat] *= r
        total = sum(post.values())
        return {k: v / total for k, v in post.items()}, fired

    def label(self, frame: FrameInput, depth: DepthResult, segments: Segments) -> list[MaterialLabel]:
        maps = _image_maps(frame.rgb)
        points = normals = line = gray = None
        if self.use_structure and any(lab in STRUCTURE_LABELS for lab in segments.labels):
            d = np.asarray(depth.depth_m, np.float32)
            if d.shape == frame.rgb.shape[:2] and np.isfinite(d).any() and (d > 0).any():
                points = points_from_depth(d, frame.intrinsics)
                normals = normals_from_points(points, max(1, round(frame.intrinsics.width / 320)))
                line = _line_strength(frame.rgb)
                gray = cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2GRAY).astype(np.float32) + 1.0
        out = []
        for k, label in enumerate(segments.labels):
            mask = segments.segment_id == k
            feats = _features(maps, mask)
            if points is not None and label in STRUCTURE_LABELS:
                st = surface_structure(line, points, mask, frame.intrinsics.fx, normals=normals,
                                       gray=gray)
                feats = dataclasses.replace(feats, structure=st)
            post, fired = self.posterior(label, feats)
            mat = max(post, key=post.get)
            reason = (
                f"prior[{label}] x rules {fired or 'none'}; hue {feats.hue_deg:.0f} deg, "
                f"sat {feats.saturation:.2f}, mottling {feats.lf_contrast:.3f}, "
                f"grout {feats.grout_frac:.3f}, coherence {feats.coherence:.2f}"
            )
            st = feats.structure
            if st is not None and st.n_cells:
                reason += (f"; joints: lines {st.line_frac:.3f}, spacing {st.period_h_m:.2f} m "
                           f"(score {st.score_h:.2f}) / {st.period_v_m:.2f} m "
                           f"(score {st.score_v:.2f}), bond {st.bond:.2f}")
            out.append(MaterialLabel(mat, float(post[mat]), reason))
        return out
