"""Built-in segmentation on an analytic corridor: exact depth, known masks and labels."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.reconstruct.segment_builtin import (
    BuiltinSegments,
    SegmentContext,
    SegmenterConfig,
    region_geometry,
)
from sim2radar.reconstruct.segment_builtin_doors import grow_doors, wall_openings, wall_planes
from sim2radar.reconstruct.segment_builtin_labels import vertical_label
from sim2radar.reconstruct.segment_builtin_walls import flush_with_walls, proud_of_walls, wall_plane
from sim2radar.reconstruct.synthetic import corridor_frame
from sim2radar.reconstruct.types import DepthResult, FrameInput, ReconstructionInputError
from sim2radar.vocab import SEMANTIC_CLASSES, semantic_id


@pytest.fixture(scope="module")
def frames():
    return [corridor_frame(256, 192, seed=s) for s in (1, 3)]


def _semantic(seg):
    lut = np.array([semantic_id(s) for s in seg.labels] + [0])
    return lut[seg.segment_id]


def _iou(a, b):
    return (a & b).sum() / max((a | b).sum(), 1)


def test_structure_classes_are_recovered(frames):
    for f in frames:
        backend = BuiltinSegments()
        seg = backend.segment(FrameInput(f.rgb, f.intrinsics), DepthResult(f.depth_m))
        sem = _semantic(seg)
        for name in ("wall", "floor", "ceiling"):
            c = semantic_id(name)
            assert _iou(sem == c, f.semantic_id == c) > 0.85, name
        # gravity: the camera is level, so up is -y
        assert np.dot(seg.up_cam, [0, -1, 0]) > np.cos(np.radians(1))
        assert seg.info["floor_z_m"] == pytest.approx(-1.5, abs=0.05)


def test_the_nearest_visible_door_is_segmented_as_a_door(frames):
    found = 0
    for f in frames:
        seg = BuiltinSegments().segment(FrameInput(f.rgb, f.intrinsics), DepthResult(f.depth_m))
        sem = _semantic(seg)
        door = semantic_id("door")
        inst = [i for i, o in enumerate(f.objects) if o["semantic"] == "door"]
        sizes = [(f.instance_id == i).sum() for i in inst]
        nearest = inst[int(np.argmax(sizes))]
        if _iou(sem == door, f.instance_id == nearest) > 0.3 or (
            ((sem == door) & (f.instance_id == nearest)).sum() > 0.7 * max(sizes)
        ):
            found += 1
        # no door label on the floor or ceiling
        assert not ((sem == door) & np.isin(f.semantic_id, [2, 3])).sum() > 0.02 * (sem == door).sum()
    assert found == len(frames)


def test_region_geometry_of_a_wall(frames):
    f = frames[0]
    from sim2radar.reconstruct.backproject import level_from_camera, points_from_depth

    pl = points_from_depth(f.depth_m, f.intrinsics) @ level_from_camera([0, -1, 0])[:3, :3].T
    wall = f.instance_id == next(i for i, o in enumerate(f.objects) if o["name"] == "wall_end")
    g = region_geometry(pl, wall)
    assert g.vertical_cos < 0.05  # vertical plane
    assert g.planarity < 1e-3
    assert g.height_m == pytest.approx(2.7, abs=0.15)

    assert g.fill > 0.9  # a whole wall: its pixels cover their convex hull


def test_a_region_s_hull_from_its_rows_ends_is_the_hull_of_all_its_pixels():
    """The fill's convex hull is taken over each row's first and last pixel: the same hull
    vertices ``cv2.convexHull`` gives for every pixel (blobs, scattered pixels, one row, one
    column, polygons), so the fill is the same number."""
    import cv2

    from sim2radar.reconstruct.segment_builtin_geometry import row_ends

    rng = np.random.default_rng(7)
    for k in range(200):
        m = np.zeros((40, 50), np.uint8)
        if k % 5 == 0:
            m[:] = rng.random((40, 50)) < 0.05
        elif k % 5 == 1:
            m[rng.integers(0, 40), rng.integers(0, 25):rng.integers(26, 50)] = 1
        elif k % 5 == 2:
            m[rng.integers(0, 20):rng.integers(21, 40), rng.integers(0, 50)] = 1
        elif k % 5 == 3:
            cv2.fillPoly(m, [rng.integers(0, 40, (int(rng.integers(3, 8)), 2)).astype(np.int32)], 1)
        else:
            m[:] = cv2.GaussianBlur(rng.random((40, 50)), (0, 0), 2.5) > 0.53
        mask = m.astype(bool)
        if mask.sum() < 3:
            continue
        every = cv2.convexHull(np.argwhere(mask)[:, ::-1].astype(np.int32))
        assert np.array_equal(cv2.convexHull(row_ends(mask)), every), k


def test_empty_depth_is_a_clear_error(frames):
    f = frames[0]
    with pytest.raises(ReconstructionInputError, match="no segments"):
        BuiltinSegments().segment(FrameInput(f.rgb, f.intrinsics),
                                  DepthResult(np.zeros_like(f.depth_m)))


def test_labels_are_in_the_vocabulary(frames):
    f = frames[1]
    seg = BuiltinSegments().segment(FrameInput(f.rgb, f.intrinsics), DepthResult(f.depth_m))
    assert set(seg.labels) <= set(SEMANTIC_CLASSES)
    assert seg.segment_id.max() == seg.n_segments - 1
    assert len(seg.scores) == seg.n_segments
    assert (seg.segment_id >= 0).all()  # every pixel, with or without depth, has a segment
    no_fill = BuiltinSegments(fill_no_depth=False).segment(
        FrameInput(f.rgb, f.intrinsics), DepthResult(np.where(np.arange(f.depth_m.shape[0])[:, None] > 150, 0, f.depth_m)))
    assert (no_fill.segment_id[151:] == -1).all() and (no_fill.segment_id[:150] >= 0).all()


@pytest.mark.parametrize("corruption", ["missing", "extrapolated"])
def test_floor_band_without_true_depth_is_floor(frames, corruption):
    # LiDAR-completed depth: no depth under the lowest beam, or depth extrapolated from the
    # walls (points below the floor). Both bands see the floor.
    f = frames[0]
    band = np.arange(f.depth_m.shape[0])[:, None] >= 150
    bad = np.where(band, 0.0 if corruption == "missing" else 3.0 * f.depth_m, f.depth_m)
    seg = BuiltinSegments().segment(FrameInput(f.rgb, f.intrinsics), DepthResult(bad))
    gt_floor = (f.semantic_id == semantic_id("floor")) & band
    assert gt_floor.sum() > 500
    pred_floor = _semantic(seg) == semantic_id("floor")
    assert (pred_floor & gt_floor).sum() / gt_floor.sum() > 0.9
    # the walls in the band (their rays meet the floor plane behind the wall) stay walls
    assert (pred_floor & band & ~gt_floor).sum() < 0.05 * (band & ~gt_floor).sum()


# a level-frame pixel grid ahead of the camera: columns span y 2 .. -2 m, rows z 1.5 .. -1.3 m
# (the floor level)
GRID_H, GRID_W = 120, 160
GRID_Y = np.linspace(2.0, -2.0, GRID_W)
GRID_Z = np.linspace(1.5, -1.3, GRID_H)


def _grid_points(x: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 level-frame points of the grid at forward distances ``x`` (H, W)."""
    return np.stack(np.broadcast_arrays(x, GRID_Y[None, :], GRID_Z[:, None]), -1).astype(np.float32)


def _ctx(pl: np.ndarray, config: SegmenterConfig = SegmenterConfig(), **kw) -> SegmentContext:
    """The segmenter's per-call context over the grid ``pl``: floor at -1.3 m, ceiling at
    1.5 m."""
    return SegmentContext(config, pl, floor_z_m=-1.3, ceiling_z_m=1.5, **kw)


def _wall_with_door_fragment(door_lab):
    """A wall 4 m ahead (the grid), a 0.75 m wide door leaf up to 2.1 m above the floor; only
    its part below z = -0.3 is its own region."""
    h, w = GRID_H, GRID_W
    pl = _grid_points(np.full((h, w), 4.0))
    door = (np.abs(GRID_Y[None, :] - 0.0) < 0.375) & (GRID_Z[:, None] < 0.8)
    regions = np.zeros((h, w), np.int64)
    regions[door & (GRID_Z[:, None] < -0.3)] = 1
    lab = np.zeros((h, w, 3), np.float32)
    lab[...] = (60.0, 0.0, 0.0)
    lab[door] = door_lab
    return regions, pl, lab, door


def test_door_leaf_is_grown_from_its_lower_fragment_by_colour():
    regions, pl, lab, door = _wall_with_door_fragment((30.0, 30.0, 20.0))
    out, labels, _ = grow_doors(_ctx(pl, lab=lab), regions, ["wall", "clutter"], [0.8, 0.4])
    assert labels[1] == "door"
    assert _iou(out == 1, door) > 0.95  # the upper leaf joined, the wall around it did not
    # a fragment of the wall's own colour is not grown (it would swallow the wall column)
    regions, pl, lab, door = _wall_with_door_fragment((60.0, 0.0, 0.0))
    out, labels, _ = grow_doors(_ctx(pl, lab=lab), regions, ["wall", "clutter"], [0.8, 0.4])
    assert labels[1] == "clutter" and (out == 1).sum() == (regions == 1).sum()


def _geometry(borders: str, width_m=1.0, z_min=-1.25, z_max=0.6):
    from sim2radar.reconstruct.segment_builtin import SegmentGeometry

    return SegmentGeometry(50_000, np.array([3.0, 0.0, -0.3]), np.array([-1.0, 0.0, 0.0]),
                           0.01, width_m, z_min, z_max, 0.95, borders)


def test_rectangle_cut_by_the_top_and_a_side_border_is_no_door():
    """A 1 m wide, 1.85 m tall vertical rectangle on the floor is a door when only the top
    and bottom borders cut it (its width is seen); cut by the top and the left border, neither
    its height nor its width is measured — a wall near the camera fills that corner too — so
    the size rules do not call it a door."""
    cfg = SegmenterConfig()
    floor_z, ceil_z = -1.25, 1.55
    assert vertical_label(cfg, _geometry("tb"), floor_z, ceil_z, True)[0] == "door"
    assert vertical_label(cfg, _geometry(""), floor_z, ceil_z, True)[0] == "door"
    for borders in ("tl", "tr", "tbl"):
        assert vertical_label(cfg, _geometry(borders), floor_z, ceil_z, True)[0] == "wall"


@pytest.mark.parametrize(("z_max", "label"), [(0.85, "door"), (0.95, "door"), (1.15, "wall")])
def test_rectangle_taller_than_a_door_is_a_wall(z_max, label):
    """A 1 m wide vertical rectangle standing on the floor (1.25 m below the camera) is a door
    up to ``door_height_m[1]`` (2.3 m: standard leaves are at most 2.13 m, plus the error of a
    measured top); 2.4 m tall it is a wall's surface — with or without the image's top border
    cutting it (a wall facing the camera in a corner fills the same shape)."""
    for borders in ("", "t"):
        g = _geometry(borders, z_max=z_max)
        assert vertical_label(SegmenterConfig(), g, -1.25, 1.55, False)[0] == label


def _wall_with_block(front_m: float, top_m: float, turn_deg: float = 0.0):
    """A wall 4 m ahead (the grid) and a 0.8 m wide block on the floor ``front_m`` in front of
    it, ``top_m`` tall (region 1), its face turned by ``turn_deg`` about its edge at y = -0.4
    (a leaf swung out of its doorway)."""
    x = np.full((GRID_H, GRID_W), 4.0)
    block = (np.abs(GRID_Y[None, :]) < 0.4) & (GRID_Z[:, None] < -1.3 + top_m)
    face = 4.0 - front_m - (GRID_Y + 0.4) * np.tan(np.radians(turn_deg))
    x[block] = np.broadcast_to(face[None, :], x.shape)[block]
    return block.astype(np.int64), _grid_points(x)


@pytest.mark.parametrize(("front_m", "top_m", "turn_deg", "label"), [
    (0.4, 1.5, 0, "clutter"),   # a cabinet 0.4 m proud of the wall
    (0.2, 0.6, 0, "clutter"),   # a radiator or a bin 0.2 m proud
    (0.4, 2.0, 0, "clutter"),   # a tall cabinet: up to door height, but facing as the wall
    (0.06, 1.5, 0, "door"),     # 6 cm proud (below proud_m): a leaf, a frame, a panel
    (0.0, 1.9, 0, "door"),      # flush with the wall: a closed leaf
    (0.0, 2.1, 40, "door"),     # up to door height, turned 40°: an open leaf swung out
    (0.4, 2.6, 0, "door"),      # above any door (up to a ceiling): a wall's own surface
    (1.5, 1.5, 0, "door"),      # far in front: another wall's surface, not furniture on this one
])
def test_furniture_standing_proud_of_a_wall_is_clutter(front_m, top_m, turn_deg, label):
    """A door-labelled block standing 0.12–0.7 m (``proud_m``) in front of a large wall is
    furniture when below door height, or up to it but facing the same way as the wall (a
    cabinet's front: a leaf swung out of its doorway is turned by its swing); flush with the
    wall, turned, above door height or far in front of the wall it keeps its label."""
    regions, pl = _wall_with_block(front_m, top_m, turn_deg)
    _, labels, _, proud = proud_of_walls(_ctx(pl), regions, ["wall", "door"], [0.8, 0.5])
    assert labels[1] == label
    assert (1 in proud) == (label == "clutter")
    assert labels[0] == "wall"


def test_furniture_blended_into_its_wall_region_is_split_off():
    """A cabinet 0.4 m proud of the wall whose pixels the depth completion merged into the
    wall's region is split off as a ``clutter`` region (``proud_split``); the wall keeps the
    rest. With ``proud_split=False`` the region is left whole."""
    regions, pl = _wall_with_block(0.4, 1.5)
    block = regions == 1
    merged = np.zeros_like(regions)
    out, labels, _, proud = proud_of_walls(_ctx(pl), merged, ["wall"], [0.8])
    assert len(labels) == 2 and labels[1] == "clutter" and 1 in proud
    assert _iou(out == 1, block) > 0.9
    assert ((out == 0) & ~block).sum() == (~block).sum()
    out, labels, _, _ = proud_of_walls(_ctx(pl, SegmenterConfig(proud_split=False)), merged,
                                       ["wall"], [0.8])
    assert labels == ["wall"] and (out == 0).all()


@pytest.mark.parametrize(("front_m", "label"), [(0.0, "wall"), (0.02, "wall"), (0.3, "clutter")])
def test_small_region_on_a_wall_plane_is_wall(front_m, label):
    """A piece of wall too small to be a wall by size (a strip a handrail cut out) is ``wall``
    when it lies on a large wall's plane; standing proud of it, it stays ``clutter``."""
    regions, pl = _wall_with_block(front_m, 0.5)
    labels = flush_with_walls(_ctx(pl), regions, ["wall", "clutter"])
    assert labels == ["wall", label]


def test_wall_region_without_depth_is_skipped_by_the_opening_search():
    """A large ``wall`` region whose pixels all lack depth (grown over pixels the LiDAR missed)
    has no plane: the opening search passes over it instead of failing on its empty point set
    (found on a procedural frame, where it raised ``IndexError`` and failed the frame)."""
    regions, pl = _wall_with_block(0.0, 1.9)
    pl[regions == 1] = np.nan
    assert wall_plane(_ctx(pl), regions == 1) is None
    out, labels, _, boxes = wall_openings(_ctx(pl), regions, ["wall", "wall"], [0.8, 0.8])
    assert labels == ["wall", "wall"] and boxes == [] and (out == regions).all()


@pytest.mark.parametrize("split", [False, True])
def test_open_doorway_framed_by_two_wall_regions_is_a_door(split):
    """A wall 4 m ahead with an open doorway 1.0 m wide and 2.1 m high onto a room 2 m deeper.
    The doorway splits the wall: the wall left of it may be one region and the wall right of
    it (with the lintel) another. Either way the doorway is framed by the wall plane on both
    sides and is one door box, 1.0 m wide within 8 cm (pixels are 2.5 cm apart)."""
    pl = _grid_points(np.full((GRID_H, GRID_W), 4.0))
    door = np.zeros((GRID_H, GRID_W), bool)
    door[GRID_Z < 0.8, 60:100] = True
    pl[door] *= 1.5  # the same rays, 2 m further: the room seen through the doorway
    regions = np.zeros((GRID_H, GRID_W), np.int64)
    if split:
        regions[:, 100:] = 1
        regions[GRID_Z >= 0.8, 60:100] = 1
    regions[door] = 2
    _, _, _, boxes = wall_openings(_ctx(pl), regions, ["wall", "wall", "clutter"], [0.8] * 3)
    assert len(boxes) == 1
    assert boxes[0][3] == pytest.approx(1.0, abs=0.08)


def test_coplanar_wall_regions_merge_to_the_front_most_face():
    """A wall 4 m ahead and, set 8 cm into it, a recessed double door's leaves that fill more of
    the image than the wall does: one wall plane, whose face is the wall's (the front-most),
    not the larger region's — on the leaves' plane the frame around them would lie in front of
    the plane searched for doors."""
    recess = np.zeros((GRID_H, GRID_W), bool)
    recess[:, 48:] = True  # 70 % of the columns: the leaves
    pl = _grid_points(np.where(recess, 4.08, 4.0))
    regions = np.where(recess, 0, 1)
    (plane,) = wall_planes(_ctx(pl), regions, ["wall", "wall"])
    assert plane.normal @ np.array([-1.0, 0.0, 0.0]) == pytest.approx(1.0, abs=1e-3)
    assert plane.offset_m == pytest.approx(-4.0, abs=0.01)
