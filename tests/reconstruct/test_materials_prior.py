"""The ``prior`` material backend: semantic prior × colour/texture rules."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct.materials_prior import (
    PRIORS,
    PriorMaterials,
    segment_features,
    surface_structure,
)
from sim2radar.reconstruct.types import DepthResult, FrameInput, Segments
from sim2radar.vocab import MATERIAL_CLASSES

H, W = 64, 96
RNG = np.random.default_rng(0)


def _patch(kind: str) -> np.ndarray:
    """A (H, W, 3) uint8 texture of one finish, with 2 % sensor noise."""
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    if kind == "wood":
        base = np.array([0.55, 0.36, 0.18])
        mod = 1 + 0.25 * np.sin(2 * np.pi * (y / 6 + 0.3 * np.sin(x / 15)))
    elif kind == "tiles":
        base = np.array([0.6, 0.6, 0.58])
        grout = (np.minimum(x % 16, y % 16) < 1.5)
        mod = np.where(grout, 0.45, 1.0)
    elif kind == "concrete":
        base = np.array([0.45, 0.45, 0.44])
        mod = 1 + 0.5 * np.sin(x / 4.0) * np.sin(y / 3.5) + 0.03 * RNG.standard_normal((H, W))
    elif kind == "paint":
        base = np.array([0.8, 0.79, 0.75])
        mod = np.ones((H, W))
    elif kind == "grey_paint":
        base = np.array([0.3, 0.34, 0.4])
        mod = np.ones((H, W))
    elif kind == "pane":  # the dim room seen through a glazed leaf: unoriented blotches
        base = np.array([0.09, 0.09, 0.1])
        mod = 1 + 0.6 * cv2.GaussianBlur(RNG.standard_normal((H, W)), (0, 0), 1.2) / 0.25
    elif kind == "dark_brushed":  # a dark brushed-steel leaf: streaks along x
        base = np.array([0.09, 0.09, 0.1])
        streaks = cv2.GaussianBlur(RNG.standard_normal((H, W)), (0, 0), sigmaX=12, sigmaY=0.8)
        mod = 1 + 0.6 * streaks / streaks.std()
    else:
        raise ValueError(kind)
    img = base * mod[..., None] * (1 + 0.01 * RNG.standard_normal((H, W, 1)))
    return (np.clip(img, 0, 1) * 255).astype(np.uint8)


def _label(kind: str, label: str) -> str:
    rgb = _patch(kind)
    frame = FrameInput(rgb, CameraIntrinsics.from_fov(W, H, 60))
    seg = Segments(np.zeros((H, W), np.int32), (label,), np.ones(1, np.float32))
    out = PriorMaterials().label(frame, DepthResult(np.ones((H, W), np.float32)), seg)
    assert len(out) == 1 and out[0].material in MATERIAL_CLASSES and 0 < out[0].confidence <= 1
    assert out[0].reason
    return out[0].material


@pytest.mark.parametrize(
    "kind,label,expected",
    [
        ("grey_paint", "door", "metal"),       # painted fire door: the prior
        ("wood", "door", "wood"),              # wood hue + grain
        ("tiles", "floor", "ceramic_tile"),    # grout lines
        ("concrete", "door", "metal"),         # mottling alone does not make a door concrete
        ("paint", "wall", "plasterboard"),     # smooth paint
        ("paint", "window", "glass"),
        ("grey_paint", "fire_extinguisher", "metal"),
        ("paint", "ceiling", "plasterboard"),
        ("pane", "door", "glass"),             # a dim, unoriented view through the glass
        ("dark_brushed", "door", "metal"),     # as dark and textured, but streaked
    ],
)
def test_prior_and_rules(kind, label, expected):
    assert _label(kind, label) == expected


def test_features_measure_grain_and_grout():
    full = np.ones((H, W), bool)
    wood = segment_features(_patch("wood"), full)
    tiles = segment_features(_patch("tiles"), full)
    paint = segment_features(_patch("paint"), full)
    assert 12 <= wood.hue_deg <= 48 and wood.coherence > 0.5
    assert tiles.grout_frac > 0.05 and paint.grout_frac < 0.01
    assert paint.lf_contrast < 0.02 and segment_features(_patch("concrete"), full).lf_contrast > 0.12


def test_priors_are_distributions_over_the_vocabulary():
    for label, row in PRIORS.items():
        assert set(row) <= set(MATERIAL_CLASSES), label
        assert sum(row.values()) == pytest.approx(1.0, abs=1e-6), label


def test_prior_override_and_validation():
    backend = PriorMaterials({"door": {"wood": 1.0}}, use_rules=False)
    post, fired = backend.posterior("door", segment_features(_patch("grey_paint"), np.ones((H, W), bool)))
    assert post == {"wood": 1.0} and fired == []
    with pytest.raises(ValueError, match="unknown material"):
        PriorMaterials({"door": {"steel": 1.0}})
    with pytest.raises(ValueError, match="unknown label"):
        PriorMaterials({"doorway": {"metal": 1.0}})


# --- joint-line structure on rectified surfaces, with the procedural worlds' own textures ----

def _wall_image(texture: str, scale_m: float, contrast: float, *, distance_m: float = 2.0,
                yaw_deg: float = 0.0, seed: int = 3, hw=(120, 160)):
    """Render a textured plane (a wall facing the camera, turned by ``yaw_deg`` about the
    vertical) with a pinhole camera: 3×3 supersampling, 1 % noise, sRGB. Returns
    (rgb, depth_m, intrinsics)."""
    from sim2radar.worlds.appearance import texture_image
    from sim2radar.worlds.frame import Appearance

    h, w = hw
    k = CameraIntrinsics.from_fov(w, h, 60)
    tex = texture_image(Appearance((0.6, 0.6, 0.58), 0.8, 0.0, texture, scale_m, contrast, 0.0,
                                   seed))
    if tex is None:  # plain paint
        tex = np.broadcast_to(np.array([0.6, 0.6, 0.58], np.float32), (64, 64, 3))
    n_tex = tex.shape[0]
    yaw = np.radians(yaw_deg)
    nrm = np.array([np.sin(yaw), 0.0, -np.cos(yaw)])    # plane normal, facing the camera
    along = np.array([np.cos(yaw), 0.0, np.sin(yaw)])   # horizontal in-plane axis
    p0 = np.array([0.0, 0.0, distance_m])
    acc = np.zeros((h, w, 3))
    for dy in (1 / 6, 1 / 2, 5 / 6):
        for dx in (1 / 6, 1 / 2, 5 / 6):
            jj, ii = np.meshgrid(np.arange(w) + dx, np.arange(h) + dy)
            ray = np.stack([(jj - k.cx) / k.fx, (ii - k.cy) / k.fy, np.ones_like(jj)], -1)
            t = (p0 @ nrm) / (ray @ nrm)
            q = ray * t[..., None] - p0
            u = (q @ along) / scale_m
            v = -q[..., 1] / scale_m
            acc += tex[(np.floor(v * n_tex) % n_tex).astype(int),
                       (np.floor(u * n_tex) % n_tex).astype(int)]
    lin = acc / 9 * (1 + 0.01 * RNG.standard_normal((h, w, 1)))
    rgb = (np.clip(lin, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)
    jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    ray = np.stack([(jj - k.cx) / k.fx, (ii - k.cy) / k.fy, np.ones_like(jj)], -1)
    depth = ((p0 @ nrm) / (ray @ nrm)).astype(np.float32)  # z-depth (ray z = 1)
    return rgb, depth, k


def _label_wall(texture, scale_m, contrast, label="wall", **kw):
    rgb, depth, k = _wall_image(texture, scale_m, contrast, **kw)
    h, w = depth.shape
    seg = Segments(np.zeros((h, w), np.int32), (label,), np.ones(1, np.float32))
    out = PriorMaterials().label(FrameInput(rgb, k), DepthResult(depth), seg)
    return out[0]


@pytest.mark.parametrize("yaw_deg", [0.0, 35.0])
def test_block_masonry_reads_as_concrete(yaw_deg):
    lab = _label_wall("blocks", 0.4, 0.3, yaw_deg=yaw_deg)
    assert lab.material == "concrete", lab.reason
    assert "bond" in lab.reason or "block courses" in lab.reason


def test_tiles_formwork_and_paint_on_walls():
    tile = _label_wall("tiles", 0.6, 0.25)             # 0.3 m tiles
    assert tile.material == "ceramic_tile" and "grout grid" in tile.reason, tile.reason
    form = _label_wall("formwork", 1.2, 0.35)
    assert form.material == "concrete" and "formwork" in form.reason, form.reason
    paint = _label_wall("plain", 1.0, 0.0)
    assert paint.material == "plasterboard" and "smooth" in paint.reason, paint.reason


def test_ceilings_grid_versus_concrete_soffit():
    grid = _label_wall("ceiling_grid", 0.6, 0.4, label="ceiling")
    assert grid.material == "plasterboard" and "suspended-ceiling grid" in grid.reason, grid.reason
    slab = _label_wall("formwork", 1.2, 0.35, label="ceiling")
    assert slab.material == "concrete", slab.reason


def test_surface_structure_measures_spacing_in_metres_and_the_bond():
    """Spacing is metric (independent of distance); running bond staggers, tiles do not."""
    from sim2radar.reconstruct.backproject import points_from_depth

    for distance in (1.5, 2.5):
        rgb, depth, k = _wall_image("blocks", 0.4, 0.35, distance_m=distance, hw=(240, 320))
        from sim2radar.reconstruct.materials_prior import _line_strength

        st = surface_structure(_line_strength(rgb), points_from_depth(depth, k),
                               np.ones(depth.shape, bool), k.fx)
        assert st.period_h_m == pytest.approx(0.2, abs=0.02) and st.score_h > 0.6
        assert st.bond > 0.3
    rgb, depth, k = _wall_image("tiles", 0.6, 0.3, hw=(240, 320))
    from sim2radar.reconstruct.materials_prior import _line_strength

    st = surface_structure(_line_strength(rgb), points_from_depth(depth, k),
                           np.ones(depth.shape, bool), k.fx)
    assert st.period_h_m == pytest.approx(0.3, abs=0.03)
    assert st.period_v_m == pytest.approx(0.3, abs=0.03) and st.bond < 0.2
    # too far to resolve joints: not measured (the image-space rules take over)
    rgb, depth, k = _wall_image("blocks", 0.4, 0.35, distance_m=12.0)
    st = surface_structure(_line_strength(rgb), points_from_depth(depth, k),
                           np.ones(depth.shape, bool), k.fx)
    assert st.n_cells == 0


@pytest.mark.parametrize(("ph", "sh", "pv", "sv", "tile"), [
    (0.33, 0.28, 0.33, 0.52, True),    # a square grid, both directions faint
    (0.59, 0.50, 0.25, 0.61, True),    # every other joint fainter: one period doubled
    (0.30, 0.80, float("nan"), 0.0, True),   # strong lines at tile spacing, one direction
    (0.30, 0.45, float("nan"), 0.0, False),  # faint lines in one direction only
    (0.60, 0.87, 0.21, 0.11, False),   # formwork panel joints, no tile period across
    (0.30, 0.28, 0.30, 0.10, False),   # tile spacing, but the second direction is noise
    (0.40, 0.30, 0.20, 0.30, False),   # 0.2 m: block courses, not a tile
])
def test_wall_tile_grid_from_both_directions(ph, sh, pv, sv, tile):
    """Wall tiles show a grout grid at tile spacing: strong lines in one direction, or faint
    lines in both at the same spacing (or one at twice it). The rule decides on the measured
    structure alone, and a tile grid outweighs a formwork-like 0.6 m period."""
    from sim2radar.reconstruct.materials_prior import AppearanceFeatures, SurfaceStructure

    st = SurfaceStructure(period_h_m=ph, score_h=sh, period_v_m=pv, score_v=sv, bond=0.0,
                          line_frac=0.035, mottling=0.07, extent_m=2.0, n_cells=3000)
    f = AppearanceFeatures(0.0, 0.1, 0.6, 0.04, 0.0, 0.1, 50_000, st)
    post, fired = PriorMaterials().posterior("wall", f)
    assert ("tile grout grid" in fired) == tile, fired
    assert (max(post, key=post.get) == "ceramic_tile") == tile, (post, fired)


def test_plane_masks_split_a_segment_into_its_planes_largest_first_ties_to_the_lower_cell():
    """Two walls at a corner in one segment (as one oracle instance can hold both walls of a
    corridor): the larger wall comes out first, then the other; at equal sizes the wall whose
    rounded normal is lower in (x, y, z) order is taken first, and of two equally full offsets
    along a normal the nearer one, as a sort-based mode (np.unique + argmax) would pick."""
    from sim2radar.reconstruct.materials_prior import _plane_masks

    h, w = 60, 100
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)

    def corner(split: int):
        left = xx < split                       # wall 1: x = 2 m (normal -x); wall 2: y = 3 m
        pts = np.where(left[..., None], np.stack([np.full_like(xx, 2.0), xx * 0.02, yy * 0.02], -1),
                       np.stack([xx * 0.02, np.full_like(xx, 3.0), yy * 0.02], -1))
        nrm = np.where(left[..., None], np.array([-1.0, 0, 0]), np.array([0, -1.0, 0]))
        return pts, nrm, left

    pts, nrm, left = corner(70)                 # 70 % of the pixels on wall 1
    planes = _plane_masks(pts, nrm, np.ones((h, w), bool), min_px=500)
    assert [p.sum() for p in planes] == [left.sum(), (~left).sum()]
    assert np.array_equal(planes[0], left)
    pts, nrm, left = corner(50)                 # a tie: (-1, 0, 0) < (0, -1, 0)
    planes = _plane_masks(pts, nrm, np.ones((h, w), bool), min_px=500)
    assert np.array_equal(planes[0], left) and np.array_equal(planes[1], ~left)
    # one normal, two parallel sheets 0.5 m apart with the same pixel count: the nearer first
    pts = np.stack([np.where(xx < 50, 2.0, 2.5), xx * 0.02, yy * 0.02], -1)
    nrm = np.broadcast_to(np.array([1.0, 0, 0]), pts.shape)
    planes = _plane_masks(pts, nrm, np.ones((h, w), bool), min_px=500)
    assert len(planes) == 2 and np.array_equal(planes[0], xx < 50)
