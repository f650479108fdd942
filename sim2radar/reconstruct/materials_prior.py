"""Stage 3 ``prior`` backend: semantic prior × colour/texture evidence, no learned weights.

Each segment starts from a material distribution for its semantic label (building practice:
fire-corridor doors are mostly metal, corridor floors tile or concrete, walls plasterboard or
concrete, windows glass, handrails and extinguishers metal — :data:`PRIORS`). Appearance
features measured on the segment's pixels then multiply the prior by likelihood ratios
(:data:`RULES`), and the posterior's arg-max is the label:

* wood: hue 15–45°, saturation 0.3–0.8, and an oriented grain (structure-tensor coherence);
* ceramic tile: thin dark grout lines (pixels much darker than their neighbourhood);
* raw concrete: grey (low saturation) with strong low-frequency mottling;
* brushed metal: grey with strongly oriented streaks;
* plastic: saturated, untextured colour on clutter / floors.

The reason string lists the features and the rules that fired, so a wrong label can be traced.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from sim2radar.reconstruct.types import (
    MATERIAL_BACKENDS,
    DepthResult,
    FrameInput,
    MaterialLabel,
    Segments,
)
from sim2radar.vocab import MATERIAL_CLASSES, SEMANTIC_CLASSES

__all__ = ["PRIORS", "AppearanceFeatures", "segment_features", "PriorMaterials"]

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
    """

    hue_deg: float
    saturation: float
    value: float
    lf_contrast: float
    grout_frac: float
    coherence: float
    n_px: int


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


def _is_wood(f: AppearanceFeatures) -> bool:
    return 12 <= f.hue_deg <= 48 and 0.3 <= f.saturation <= 0.85 and 0.1 <= f.value <= 0.8


#: (name, test, {material: likelihood ratio}) — applied in order; each that fires multiplies.
RULES: tuple = (
    ("wood hue + grain", lambda f: _is_wood(f) and (f.coherence > 0.3 or f.lf_contrast > 0.05),
     {"wood": 8.0}),
    ("wood hue", lambda f: _is_wood(f) and f.coherence <= 0.3 and f.lf_contrast <= 0.05,
     {"wood": 3.0}),
    ("grout lines", lambda f: f.grout_frac > 0.03 and not _is_wood(f), {"ceramic_tile": 6.0}),
    # raw concrete (texture contrast 0.10-0.25); lighting and path-tracing noise alone reach
    # ~0.1 of band-pass contrast on plain walls, so only strong mottling counts
    ("grey mottling", lambda f: f.lf_contrast > 0.12 and f.saturation < 0.2
     and f.grout_frac < 0.03, {"concrete": 4.0}),
    ("smooth paint", lambda f: f.lf_contrast < 0.02 and f.grout_frac < 0.01,
     {"plasterboard": 1.5, "metal": 1.3}),
    ("brushed streaks", lambda f: f.coherence > 0.6 and f.saturation < 0.15
     and f.lf_contrast > 0.02, {"metal": 2.0}),
    ("saturated plain colour", lambda f: f.saturation > 0.45 and f.lf_contrast < 0.03
     and not _is_wood(f), {"plastic": 2.0}),
)


@MATERIAL_BACKENDS.register("prior")
class PriorMaterials:
    """Semantic prior × appearance rules (see the module docstring).

    Parameters
    ----------
    priors : dict, optional — ``{label: {material: probability}}`` overriding :data:`PRIORS`
        per label (each row must use ``vocab.MATERIAL_CLASSES`` names).
    use_rules : bool — False gives the prior's arg-max only.
    """

    def __init__(self, priors: dict | None = None, *, use_rules: bool = True) -> None:
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

    def posterior(self, label: str, features: AppearanceFeatures) -> tuple[dict[str, float], list[str]]:
        """Normalised material distribution for one segment and the names of the rules that fired."""
        post = dict(self.priors.get(label, self.priors["unknown"]))
        fired = []
        if self.use_rules:
            for name, test, ratios in RULES:
                if test(features):
                    fired.append(name)
                    for mat, r in ratios.items():
                        if mat in post:
                            post[mat] *= r
        total = sum(post.values())
        return {k: v / total for k, v in post.items()}, fired

    def label(self, frame: FrameInput, depth: DepthResult, segments: Segments) -> list[MaterialLabel]:
        maps = _image_maps(frame.rgb)
        out = []
        for k, label in enumerate(segments.labels):
            feats = _features(maps, segments.segment_id == k)
            post, fired = self.posterior(label, feats)
            mat = max(post, key=post.get)
            reason = (
                f"prior[{label}] x rules {fired or 'none'}; hue {feats.hue_deg:.0f} deg, "
                f"sat {feats.saturation:.2f}, mottling {feats.lf_contrast:.3f}, "
                f"grout {feats.grout_frac:.3f}, coherence {feats.coherence:.2f}"
            )
            out.append(MaterialLabel(mat, float(post[mat]), reason))
        return out
