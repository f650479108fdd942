"""OpenPCDet custom layout: round trip and clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.datasets import (
    DatasetError,
    Frame,
    OpenPCDetDataset,
    make_door_frames,
    read_labels,
    write_dataset,
    write_synthetic_dataset,
)


def test_round_trip(tmp_path):
    frames = make_door_frames(3, seed=0, points_per_frame=300)
    ds = write_dataset(tmp_path, frames, {"train": ["000000", "000001"], "test": ["000002"]})
    assert ds.splits() == ["test", "train"]
    assert ds.split_ids("train") == ["000000", "000001"]
    back = ds.frame("000001")
    np.testing.assert_array_equal(back.points, frames[1].points)
    np.testing.assert_allclose(back.boxes, frames[1].boxes, atol=1e-6)
    assert back.names == frames[1].names and back.points.dtype == np.float32
    # label text is OpenPCDet's: x y z dx dy dz heading class_name
    first = (tmp_path / "labels" / "000001.txt").read_text().splitlines()[0].split()
    assert len(first) == 8 and first[-1] == "door"


def test_frames_without_boxes_and_class_selection(tmp_path):
    pts = np.zeros((5, 4), np.float32)
    f = Frame("a", pts, np.array([[1, 0, 0, 1, 0.2, 2, 0], [2, 0, 0, 1, 1, 1, 0]], np.float32),
              ("door", "window"))
    empty = Frame("b", pts, np.zeros((0, 7), np.float32), ())
    ds = write_dataset(tmp_path, [f, empty], {"train": ["a", "b"]})
    assert ds.frame("b").boxes.shape == (0, 7)
    assert ds.frame("a").select(["door"]).names == ("door",)


def test_clear_errors(tmp_path):
    with pytest.raises(DatasetError, match="does not exist"):
        OpenPCDetDataset(tmp_path / "nope")
    (tmp_path / "points").mkdir()
    with pytest.raises(DatasetError, match="labels/"):
        OpenPCDetDataset(tmp_path)
    write_synthetic_dataset(tmp_path / "d", 2, 1, 1, points_per_frame=100)
    root = tmp_path / "d"
    ds = OpenPCDetDataset(root, num_point_features=5)
    with pytest.raises(DatasetError, match=r"4 columns.*num_point_features: 4"):
        ds.frame("000000")
    with pytest.raises(DatasetError, match=r"available splits: \['test', 'train', 'val'\]"):
        ds.split_ids("training")
    lbl = root / "labels" / "000001.txt"
    lbl.write_text(lbl.read_text() + "1 2 3 1 1 door\n")
    with pytest.raises(DatasetError, match=r"000001\.txt:\d+: expected 8 fields"):
        read_labels(lbl)
    lbl.write_text("1 2 3 1 0 1 0 door\n")
    with pytest.raises(DatasetError, match="must be > 0"):
        read_labels(lbl)
    np.save(root / "points" / "000002.npy", np.full((3, 4), np.nan, np.float32))
    with pytest.raises(DatasetError, match="NaN"):
        OpenPCDetDataset(root).frame("000002")
    with pytest.raises(DatasetError, match="not written"):
        write_dataset(tmp_path / "e", [], {"train": ["zzz"]})


def test_synthetic_frames_look_like_ifr():
    frames = make_door_frames(5, seed=1)
    assert all(f.points.shape == (2000, 4) for f in frames)
    assert all(1 <= len(f.boxes) <= 3 for f in frames)
    b = np.concatenate([f.boxes for f in frames])
    assert (b[:, 3] >= 0.85).all() and (b[:, 3] <= 1.0).all()   # width
    assert (b[:, 5] >= 2.0).all() and (b[:, 5] <= 2.1).all()    # height
    np.testing.assert_allclose(b[:, 2] - b[:, 5] / 2, -1.05, atol=1e-5)  # on the floor
    again = make_door_frames(5, seed=1)
    np.testing.assert_array_equal(frames[3].points, again[3].points)


def test_a_smaller_export_into_the_same_folder_leaves_no_stale_frames(tmp_path):
    rng = np.random.default_rng(0)
    big = [Frame(f"f{i}", rng.normal(size=(5, 4)).astype(np.float32), np.zeros((0, 7)), ())
           for i in range(4)]
    write_dataset(tmp_path, big, {"train": ["f0", "f1"], "val": ["f2"], "test": ["f3"]})
    (tmp_path / "notes.md").write_text("mine")
    ds = write_dataset(tmp_path, big[:2], {"train": ["f0"], "test": ["f1"]})
    assert sorted(p.stem for p in (tmp_path / "points").glob("*.npy")) == ["f0", "f1"]
    assert sorted(p.stem for p in (tmp_path / "labels").glob("*.txt")) == ["f0", "f1"]
    assert ds.splits() == ["test", "train"]  # val.txt of the earlier export is gone
    assert (tmp_path / "notes.md").read_text() == "mine"  # other files are left alone
