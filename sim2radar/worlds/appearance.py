"""Optical appearance priors and procedural textures for world objects.

Each material class has a palette of plausible finishes (paints, raw surfaces). Palettes overlap
on purpose (painted metal, painted plasterboard and painted concrete share colours; wood doors may
be painted grey), so that colour alone does not give the material away. What does carry the
material, as in real buildings, is the surface structure a person (or a VLM) reads:

* concrete-block walls: mortar joints in running bond, 0.4 m × 0.2 m blocks (``blocks``), raw or
  painted (painting keeps the recessed joints visible);
* poured concrete walls / slab soffits: formwork panel joints (1.2 m × 0.6 m), tie holes and
  mottling (``formwork``); concrete floors: mottling with aggregate speckle (``mottled``);
* plasterboard: smooth paint (``plain`` or a faint orange-peel ``speckle``); suspended ceiling
  boards: a 0.6 m grid with fissured boards (``ceiling_grid``);
* ceramic tiles: grout grids (``tiles``, 0.25–0.33 m on walls, 0.3–0.6 m on floors);
* wood: grain (``grain``; painted wood keeps a faint grain); metal doors: smooth paint with a
  sheen (low roughness); vinyl floors: fine speckle with a sheen.

Textures are periodic images (``texture_image``) tiled over world-space planar UVs at render time
(one image spans ``texture_scale_m`` in both directions; image rows run along the second UV axis,
which is height on walls). Colours are linear RGB reflectances in [0, 1].
"""

from __future__ import annotations

import numpy as np

from sim2radar.worlds.frame import Appearance

__all__ = ["sample_appearance", "texture_image", "TEXTURES"]

TEXTURES = ("plain", "noise", "tiles", "grain", "brushed", "speckle", "blocks", "formwork",
            "ceiling_grid", "mottled")

#: Concrete block (CMU) face size [m] (0.4 long × 0.2 high courses; one texture period spans
#: 0.4 m: one block length and two courses in running bond).
BLOCK_PERIOD_M = 0.4
#: Formwork panel size [m] (1.2 × 0.6); one texture period spans 1.2 m.
FORMWORK_PERIOD_M = 1.2
#: Suspended-ceiling grid pitch [m].
CEILING_GRID_M = 0.6

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
        # smooth (often powder-coated) paint with a sheen
        tex = "plain" if u() < 0.8 else "speckle"
        return Appearance(_jitter(rng, _pick(rng, palette)), u(0.2, 0.45), 0.0, tex,
                          u(0.3, 1.0), u(0.01, 0.03), 0.0, seed)
    if material == "wood":
        if u() < 0.3 and not floor:  # painted wood: the grain still shows through the paint
            return Appearance(_jitter(rng, _pick(rng, _DOOR_PAINTS)), u(0.45, 0.75), 0.0,
                              "grain", u(0.4, 1.0), u(0.06, 0.10), 0.0, seed)
        return Appearance(_jitter(rng, _pick(rng, _WOODS)), u(0.35, 0.7), 0.0, "grain",
                          u(0.4, 1.2), u(0.15, 0.35), 0.0, seed)
    if material == "plasterboard":
        if kind == "ceiling" and u() < 0.6:  # suspended ceiling boards on a 0.6 m grid
            return Appearance(_jitter(rng, _pick(rng, _PAINTS[:3] + [(0.85, 0.85, 0.83)]), 0.04),
                              u(0.8, 0.95), 0.0, "ceiling_grid", CEILING_GRID_M, u(0.35, 0.5),
                              0.0, seed)
        # smooth paint (a faint orange-peel roller texture at most)
        tex = "plain" if u() < 0.7 else "speckle"
        return Appearance(_jitter(rng, _pick(rng, _PAINTS)), u(0.75, 0.95), 0.0, tex,
                          u(0.5, 2.0), u(0.01, 0.03), 0.0, seed)
    if material == "concrete":
        painted = u() < 0.4
        color = _jitter(rng, _pick(rng, _PAINTS if painted else _GREYS))
        if floor:  # slab: blotchy mottling and aggregate speckle (sealed / painted: weaker)
            return Appearance(color, u(0.45, 0.7) if painted else u(0.8, 1.0), 0.0, "mottled",
                              u(0.8, 1.5), u(0.15, 0.22) if painted else u(0.22, 0.35), 0.0,
                              seed)
        if kind != "ceiling" and u() < 0.55:  # concrete-block masonry, running bond
            return Appearance(color, u(0.75, 0.95), 0.0, "blocks", BLOCK_PERIOD_M,
                              u(0.25, 0.35) if painted else u(0.35, 0.5), 0.0, seed)
        # poured concrete: formwork panel joints, tie holes, mottling
        return Appearance(color, u(0.8, 1.0), 0.0, "formwork", FORMWORK_PERIOD_M,
                          u(0.25, 0.32) if painted else u(0.3, 0.42), 0.0, seed)
    if material == "ceramic_tile":
        scale = u(0.3, 0.6) if floor else u(0.25, 0.33)
        return Appearance(_jitter(rng, _pick(rng, _TILES)), u(0.15, 0.45), 0.0, "tiles",
                          2 * scale, u(0.15, 0.35), 0.0, seed)
    if material == "fabric":
        return Appearance(_jitter(rng, _pick(rng, _FABRICS)), 1.0, 0.0, "speckle", u(0.3, 1.0),
                          u(0.10, 0.25), 0.0, seed)
    if material == "plastic":
        if floor:  # vinyl sheet flooring: fine chip speckle with a sheen, welded seams unseen
            return Appearance(_jitter(rng, _pick(rng, _PLASTICS + _TILES)), u(0.3, 0.5), 0.0,
                              "speckle", u(0.6, 1.2), u(0.03, 0.07), 0.0, seed)
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


def _lines(coord: np.ndarray, period: float, half_width: float) -> np.ndarray:
    """1 on lines of ``half_width`` (same unit as ``coord``) every ``period``, else 0."""
    d = np.abs(((coord + period / 2) % period) - period / 2)
    return (d < half_width).astype(np.float64)


#: Texture resolution [px per period] of the kinds with thin joint lines.
_FINE_SIZE = {"blocks": 128, "formwork": 256, "ceiling_grid": 128, "mottled": 128}


def texture_image(app: Appearance, size: int | None = None) -> np.ndarray | None:
    """The periodic texture of ``app`` as a (size, size, 3) float32 linear-RGB image, or ``None``
    for untextured (``plain``) appearances. One image spans ``texture_scale_m`` metres; ``size``
    defaults to 64 px (128–256 for kinds with thin joints, so a 1 cm joint spans ≥ 2 px)."""
    if app.texture == "plain" or app.texture_contrast <= 0:
        return None
    size = size or _FINE_SIZE.get(app.texture, 64)
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
    elif app.texture == "blocks":
        # running bond: one period = one block length (u) × two courses (v); 10 mm joints
        joint = 0.010 / BLOCK_PERIOD_M  # in period units
        course = (y * 2).astype(int) % 2
        xs = (x + 0.5 * course) % 1.0
        block_id = course * 2 + (xs < 0.5)
        block_var = rng.uniform(-0.12, 0.12, 4)[block_id]
        mod = block_var + 0.25 * rng.uniform(-1, 1, (size, size)) + 0.2 * _periodic_noise(
            rng, size, 1.0)
        bed = _lines(y, 0.5, joint / 2)          # horizontal (bed) joints every course
        head = _lines(xs, 1.0, joint / 2)        # vertical (head) joints, offset per course
        mod = np.where(np.maximum(bed, head) > 0, -1.0, mod)
    elif app.texture == "formwork":
        # 1.2 m x 0.6 m panels: thin joints, tie holes, per-panel tone, mottling
        joint = 0.02 / FORMWORK_PERIOD_M
        panel = (y * 2).astype(int) % 2
        mod = (rng.uniform(-0.15, 0.15, 2)[panel] + 0.7 * _periodic_noise(rng, size, 1.3)
               + 0.15 * rng.uniform(-1, 1, (size, size)))
        lines = np.maximum(_lines(x, 1.0, joint / 2), _lines(y, 0.5, joint / 2))
        ties = np.zeros((size, size))
        for cx in (0.25, 0.75):
            for cy in (0.25, 0.75):
                ties = np.maximum(ties, (np.hypot(x - cx, y - cy) < 0.015 / FORMWORK_PERIOD_M))
        mod = np.where((lines > 0) | (ties > 0), -1.2, mod)
    elif app.texture == "ceiling_grid":
        # 0.6 m boards in a grid of exposed T-bars (the bevelled board edges read as dark lines)
        edge = 0.024 / CEILING_GRID_M  # 24 mm (15/16") T-bar
        fissures = np.clip(rng.normal(0, 1, (size, size)), -2, 0) * 0.3
        mod = 0.2 * rng.uniform(-1, 1, (size, size)) + fissures
        grid = np.maximum(_lines(x, 1.0, edge / 2), _lines(y, 1.0, edge / 2))
        mod = np.where(grid > 0, -1.5, mod)
    elif app.texture == "mottled":
        # concrete slab: low-frequency mottling plus aggregate speckle
        mod = (0.8 * _periodic_noise(rng, size, 1.4) + 0.35 * rng.uniform(-1, 1, (size, size)))
    else:
        raise ValueError(f"unknown texture {app.texture!r}; known: {TEXTURES}")
    base = np.asarray(app.base_color, dtype=np.float64)
    img = base[None, None, :] * (1.0 + c * np.asarray(mod)[..., None])
    return np.clip(img, 0.0, 1.0).astype(np.float32)
