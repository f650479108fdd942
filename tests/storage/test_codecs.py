"""Array columns round-trip exactly, including empty rows."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from sim2radar.mesh import box_mesh
from sim2radar.storage import (
    fixed_rows,
    fixed_rows_column,
    meshes_from_table,
    meshes_to_table,
    radar_frames_from_table,
    radar_frames_to_table,
    ragged_arrays,
    ragged_column,
)


def test_ragged_round_trip_1d_and_2d_with_empty_rows():
    rng = np.random.default_rng(0)
    rows = [rng.normal(size=(n, 3)).astype(np.float32) for n in (4, 0, 7)]
    col = ragged_column(rows, pa.float32())
    assert col.type == pa.list_(pa.list_(pa.float32(), 3))
    back = ragged_arrays(pa.chunked_array([col[:1], col[1:]]))  # chunked input too
    for a, b in zip(rows, back, strict=True):
        np.testing.assert_array_equal(a, b)
    flat = [np.arange(n, dtype=np.int32) for n in (0, 2)]
    assert [list(x) for x in ragged_arrays(ragged_column(flat, pa.int32()))] == [[], [0, 1]]
    with pytest.raises(ValueError, match="second dimension"):
        ragged_column([np.zeros((1, 3)), np.zeros((1, 4))], pa.float32())


def test_fixed_rows_round_trip():
    m = np.arange(32, dtype=np.float64).reshape(2, 4, 4)
    np.testing.assert_array_equal(fixed_rows(fixed_rows_column(m, pa.float64())).reshape(2, 4, 4), m)


def test_meshes_round_trip_keep_geometry_and_labels():
    meshes = [
        box_mesh([3, 0, 1], [0.05, 1, 2], material="metal", name="door", semantic="door"),
        box_mesh([0, 0, -0.05], [10, 2, 0.1], material="concrete", name="floor", semantic="floor"),
    ]
    back = meshes_from_table(meshes_to_table(meshes))
    for a, b in zip(meshes, back, strict=True):
        np.testing.assert_array_equal(a.vertices, b.vertices)
        np.testing.assert_array_equal(a.faces, b.faces)
        assert (a.material, a.name, a.semantic) == (b.material, b.name, b.semantic)
        assert b.area_m2 == pytest.approx(a.area_m2)


def test_radar_frames_round_trip():
    pose = np.eye(4)
    pose[:3, 3] = [1.0, 2.0, 0.5]
    pts = [np.array([[3.0, 0.1, 0.0, 12.5]], np.float32), np.zeros((0, 4), np.float32)]
    boxes = [np.array([[3.0, 0, 0, 0.05, 1, 2, 0.1]]), np.zeros((0, 7))]
    table = radar_frames_to_table(
        scene_id="s", radar_to_world=[pose, np.eye(4)], points=pts, boxes=boxes,
        sim_seconds=[0.5, 0.25],
    )
    frames = radar_frames_from_table(table)
    assert [f.frame_index for f in frames] == [0, 1]
    np.testing.assert_array_equal(frames[0].points, pts[0])
    np.testing.assert_array_equal(frames[0].radar_to_world, pose)
    assert frames[0].box_labels == ["door"] and frames[1].boxes.shape == (0, 7)
    assert frames[1].points.shape == (0, 4) and frames[1].sim_seconds == 0.25
    with pytest.raises(ValueError, match="box labels"):
        radar_frames_to_table(
            scene_id="s", radar_to_world=[pose], points=pts[:1], boxes=boxes[:1], box_labels=[[]]
        )
