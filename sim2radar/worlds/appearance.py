"""Optical appearance priors and procedural textures for world objects.

Each material class has a palette of plausible finishes (paints, raw surfaces). Palettes overlap
on purpose (painted metal, painted plasterboard and painted concrete share colours; wood doors may
be painted grey), so that colour alone does not give the material away. Textures are small
periodic images (``texture_image``) tiled over world-space planar UVs at render time.
Colours are linear RGB reflectances in [0, 1].
"""

from __future__ import annotations

import numpy as np

from sim2radar.worlds.frame import Appearance

__all__ = ["sample_appearance", "texture_image", "TEXTURES"]

TEXTURES = ("plain", "noise", "tiles", "grain", "brushed", "speckle")

# Shared paint colours (linear RGB): whites, greys, pastels, institutional greens and blues.
_PAINTS = [
    (0.80, 0.79, 0.75), (0.70, 0.70, 0.70), (0.62, 0.60, 0.55), (0.55, 0.62, 0.55),
    (0.55, 0.60, 0.68), (0.75, 0.70, 0.55), (0.45, 0.45, 0.47), (0.30, 0.34, 0.40),
    (0.70, 0.62, 0.52),
]
_DOOR_PAINTS = [
    (0.45, 0.45, 0.47), (0.30, 0.34, 0.40), (0.35, 0.10, 0.08), (0.12, 0.25, 0.18),
    (0.10, 0.18, 0.35), (0.70, 0.70, 0.70), (0.80, 0.79, 0.75), (0.45, 0.30, 0.18),
    (0.55, 0.45, 0.25),
]
_WOODS = [(0.45, 0.28, 0.14), (0.55, 0.38, 0.20), (0.30, 0.17, 0.08), (0.62, 0.47, 0.30),
          (0.40, 0.30, 0.22)]
_GREYS = [(0.35, 0.35, 0.34), (0.45, 0.44, 0.42), (0.28, 0.28, 0.27), (0.55, 0.53, 0.50)]
_TILES = [(0.75, 0.74, 0.70), (0.55, 0.55, 0.55), (0.62, 0.56, 0.45), (0.50, 0.25, 0.15),
          (0.30, 0.30, 0.32), (0.60, 0.62, 0.58)]
_FABRICS = [(0.30, 0.30, 0.32), (0.15, 0.20, 0.35), (0.35, 0.12, 0.10), (0.18, 0.28, 0.18),
            (0.35, 0.28, 0.20)]
_PLASTICS = [(0.15, 0.30, 0.60), (0.20, 0.45, 0.20), (0.45, 0.45, 0.45), (0.08, 0.08, 0.08),
             (0.75, 0.62, 0.10), (0.70, 0.70, 0.68), (0.40, 0.50, 0.42)]


def _jitter(rng: np.random.Generator, rgb: tuple[float, float, float], amount: float = 0.06):
    c = np.asarray(rgb) * rng.uniform(1 - amount * 2, 1 + amount * 2) + rng.normal(0, amount / 2, 3)
    return tuple(float(x) for x in np.clip(c, 0.02, 0.92))


def _pick(rng: np.random.Generator, options: list) -> tuple[float, float, float]:
    return options[int(rng.integers(len(options)))]


def sample_appearance(
    material: str, kind: str, rng: np.random.Generator, *, emission: float = 0.0
) -> Appearance:
    """Draw an :class:`Appearance` for an object of ``material`` and ``kind``.

    Parameters
    ----------
    material : str — a material class name.
    kind : str — object kind (``door_leaf``, ``corridor_floor``, ``fire_extinguisher``, ...).
    rng : numpy Generator — the caller's appearance sub-stream.
    emission : float — radiance for light panels.
    """
    u = rng.uniform
    seed = int(rng.integers(2**31 - 1))
    floor = kind.endswith("floor")
    if kind == "light":
        return Appearance((0.9, 0.9, 0.9), 0.5, 0.0, "plain", 1.0, 0.0, emission, seed)
    if kind == "fire_extinguisher":
        color = (0.55, 0.03, 0.02) if u() < 0.9 else _pick(rng, [(0.6, 0.6, 0.6), (0.05, 0.05, 0.05)])
        return Appearance(_jitter(rng, color, 0.03), u(0.2, 0.4), 0.0, "plain", 1.0, 0.0, 0.0, seed)
    if material == "glass":
        tint = _jitter(rng, (0.85, 0.90, 0.90), 0.03)
        return Appearance(tint, 0.05, 0.0, "plain", 1.0, 0.0, 0.0, seed)
    if material == "metal":
        if kind in ("door_handle", "handrail") or u() < 0.2:
            # bare or brushed steel / aluminium
            return Appearance(_jitter(rng, (0.62, 0.62, 0.63), 0.04), u(0.15, 0.35), 1.0,
                              "brushed", u(0.3, 1.0), u(0.05, 0.15), 0.0, seed)
        palette = _DOOR_PAINTS if kind in ("door_leaf", "door_frame", "cabinet") else _PAINTS
        if kind == "radiator":
            palette = [(0.80, 0.79, 0.75), (0.70, 0.70, 0.70)]
        tex = "plain" if u() < 0.7 else "speckle"
        return Appearance(_jitter(rng, _pick(rng, palette)), u(0.3, 0.6), 0.0, tex,
                          u(0.3, 1.0), u(0.02, 0.06), 0.0, seed)
    if material == "wood":
        if u() < 0.3 and not floor:  # painted wood
            return Appearance(_jitter(rng, _pick(rng, _DOOR_PAINTS)), u(0.4, 0.7), 0.0, "plain",
                              1.0, 0.0, 0.0, seed)
        return Appearance(_jitter(rng, _pick(rng, _WOODS)), u(0.35, 0.7), 0.0, "grain",
                          u(0.4, 1.2), u(0.15, 0.35), 0.0, seed)
    if material == "plasterboard":
        tex = "plain" if u() < 0.6 else "speckle"
        return Appearance(_jitter(rng, _pick(rng, _PAINTS)), u(0.75, 0.95), 0.0, tex,
                          u(0.5, 2.0), u(0.02, 0.05), 0.0, seed)
    if material == "concrete":
        if u() < 0.4:  # painted concrete / block
            return Appearance(_jitter(rng, _pick(rng, _PAINTS)), u(0.7, 0.95), 0.0, "noise",
                              u(0.8, 2.0), u(0.03, 0.08), 0.0, seed)
        return Appearance(_jitter(rng, _pick(rng, _GREYS)), u(0.8, 1.0), 0.0, "noise",
                          u(0.8, 2.5), u(0.10, 0.25), 0.0, seed)
    if material == "ceramic_tile":
        scale = u(0.3, 0.6) if floor else u(0.2, 0.4)
        return Appearance(_jitter(rng, _pick(rng, _TILES)), u(0.15, 0.45), 0.0, "tiles",
                          2 * scale, u(0.15, 0.35), 0.0, seed)
    if material == "fabric":
        return Appearance(_jitter(rng, _pick(rng, _FABRICS)), 1.0, 0.0, "speckle", u(0.3, 1.0),
                          u(0.10, 0.25), 0.0, seed)
    if material == "plastic":
        if floor:  # vinyl flooring
            tex = "speckle" if u() < 0.6 else "tiles"
            return Appearance(_jitter(rng, _pick(rng, _PLASTICS + _TILES)), u(0.3, 0.6), 0.0,
                              tex, u(0.6, 1.2), u(0.05, 0.15), 0.0, seed)
        return Appearance(_jitter(rng, _pick(rng, _PLASTICS)), u(0.3, 0.6), 0.0, "plain", 1.0,
                          0.0, 0.0, seed)
    return Appearance(_jitter(rng, _pick(rng, _PAINTS)), 0.8, 0.0, "plain", 1.0, 0.0, 0.0, seed)


def _periodic_noise(rng: np.random.Generator, n: int, power: float) -> np.ndarray:
    """(n, n) periodic noise with a 1/f^power spectrum, scaled to [-1, 1]."""
    k = np.fft.fftfreq(n)
    kk = np.sqrt(k[:, None] ** 2 + k[None, :] ** 2)
    kk[0, 0] = 1.0
    spec = (rng.normal(size=(n, n)) + 1j * rng.normal(size=(n, n))) / kk**power
    spec[0, 0] = 0
    img = np.real(np.fft.ifft2(spec))
    return img / max(np.abs(img).max(), 1e-12)


def texture_image(app: Appearance, size: int = 64) -> np.ndarray | None:
    """The periodic texture of ``app`` as a (size, size, 3) float32 linear-RGB image, or ``None``
    for untextured (``plain``) appearances. One image spans ``texture_scale_m`` metres."""
    if app.texture == "plain" or app.texture_contrast <= 0:
        return None
    rng = np.random.default_rng(app.texture_seed)
    c = app.texture_contrast
    y, x = np.mgrid[0:size, 0:size] / size
    if app.texture == "noise":
        mod = _periodic_noise(rng, size, 1.2)
    elif app.texture == "speckle":
        mod = 0.6 * rng.uniform(-1, 1, (size, size)) + 0.4 * _periodic_noise(rng, size, 0.8)
    elif app.texture == "brushed":
        streak = _periodic_noise(rng, size, 0.5)[0]
        mod = np.broadcast_to(streak[None, :], (size, size))
    elif app.texture == "grain":
        warp = 0.15 * _periodic_noise(rng, size, 1.5)
        mod = np.sin(2 * np.pi * (4 * y + warp)) * 0.7 + 0.3 * _periodic_noise(rng, size, 1.0)
    elif app.texture == "tiles":
        # 2 x 2 tiles per period with grout lines and per-tile brightness variation
        tile_var = rng.uniform(-0.3, 0.3, (2, 2))
        mod = tile_var[(y * 2).astype(int) % 2, (x * 2).astype(int) % 2].astype(np.float64)
        gx = np.minimum((x * 2) % 1.0, 1 - (x * 2) % 1.0)
        gy = np.minimum((y * 2) % 1.0, 1 - (y * 2) % 1.0)
        grout = np.minimum(gx, gy) < 0.025
        mod = np.where(grout, -2.0, mod)
    else:
        raise ValueError(f"unknown texture {app.texture!r}; known: {TEXTURES}")
    base = np.asarray(app.base_color, dtype=np.float64)
    img = base[None, None, :] * (1.0 + c * np.asarray(mod)[..., None])
    return np.clip(img, 0.0, 1.0).astype(np.float32)
