"""`sim2radar import`: radar datasets in the formats they ship in -> the OpenPCDet custom layout
(issue #34, bring-your-own data). KITTI camera-frame labels come back in the point cloud's
frame exactly (an independent derivation of KITTI's convention writes them); class names match
without case and anything else is refused up front, naming the file; PCD files read through
pypcd4; a source without test.txt gets one carved from val, said in dataset.json."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from sim2radar.boxes import points_in_boxes
from sim2radar.cli import app
from sim2radar.datasets import OpenPCDetDataset
from sim2radar.datasets.importers import ImportSettings, import_dataset, read_kitti_calib
from sim2radar.datasets.openpcdet import DatasetError, read_metadata

# lidar (x fwd, y left, z up) -> reference camera (x right, y down, z fwd), then 0.27 m and
# 0.08 m offsets as on KITTI's car; R0_rect a small rotation about the camera's y axis
_AXES = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
_TR = np.c_[_AXES, [0.02, -0.08, -0.27]]
_A = math.radians(1.5)
_R0 = np.array([[math.cos(_A), 0, math.sin(_A)], [0, 1, 0], [-math.sin(_A), 0, math.cos(_A)]])


def _calib_text() -> str:
    return ("P2: " + " ".join(["0"] * 12) + "\n"
            "R0_rect: " + " ".join(f"{v:.12f}" for v in _R0.ravel()) + "\n"
            "Tr_velo_to_cam: " + " ".join(f"{v:.12f}" for v in _TR.ravel()) + "\n")


def _kitti_line(name: str, box: np.ndarray) -> str:
    """A KITTI label of a lidar-frame box ``x y z dx dy dz heading``, derived from KITTI's
    definition (bottom centre in the rectified camera frame, ry about camera y with ry = 0
    facing camera +x), not from the importer's formula."""
    x, y, z, dx, dy, dz, h = box
    to_rect = _R0 @ _TR[:, :3]
    bottom = to_rect @ np.array([x, y, z - dz / 2]) + _R0 @ _TR[:, 3]
    facing = to_rect @ np.array([math.cos(h), math.sin(h), 0.0])
    ry = -math.atan2(facing[2], facing[0])
    return (f"{name} 0.00 0 0.0 0 0 50 50 {dz:.6f} {dy:.6f} {dx:.6f} "
            f"{bottom[0]:.6f} {bottom[1]:.6f} {bottom[2]:.6f} {ry:.6f}\n")


def _kitti_source(root, n=6, names=("Door",), test_split=False, point_dims=7):
    rng = np.random.default_rng(3)
    truth = {}
    for sub in ("velodyne", "label_2", "calib", "ImageSets"):
        (root / sub).mkdir(parents=True)
    for i in range(n):
        fid = f"{i:06d}"
        boxes = np.array([[4.0 + i, -1.0 + 0.3 * i, 0.9, 0.9, 0.12, 2.0, 0.4 * i - 1.0],
                          [7.5, 2.0, 1.0, 1.0, 0.1, 2.1, 2.9]])
        inside = np.concatenate([b[:3] + (rng.random((20, 3)) - 0.5) * 0.5 * np.array(
            [min(b[3], b[4])] * 2 + [b[5]]) for b in boxes])
        pts = np.c_[inside, rng.random((len(inside), point_dims - 3))].astype(np.float32)
        pts.tofile(root / "velodyne" / f"{fid}.bin")
        (root / "calib" / f"{fid}.txt").write_text(_calib_text())
        (root / "label_2" / f"{fid}.txt").write_text(
            "".join(_kitti_line(names[k % len(names)], b) for k, b in enumerate(boxes))
            + "DontCare -1 -1 -10 0 0 1 1 -1 -1 -1 -1000 -1000 -1000 -10\n")
        truth[fid] = (boxes, pts)
    ids = sorted(truth)
    (root / "ImageSets" / "train.txt").write_text("\n".join(ids[:3]) + "\n")
    (root / "ImageSets" / "val.txt").write_text("\n".join(ids[3:]) + "\n")
    if test_split:
        (root / "ImageSets" / "test.txt").write_text(ids[-1] + "\n")
    return truth


def test_kitti_bin_labels_and_calib_come_back_in_the_point_cloud_frame(tmp_path):
    truth = _kitti_source(tmp_path / "src")
    doc = import_dataset(tmp_path / "src", tmp_path / "out",
                         ImportSettings(point_dims=7, columns=(0, 1, 2, 3, 5)))
    ds = OpenPCDetDataset(tmp_path / "out")
    assert doc["frames"] == 6 and doc["labels"] == 12 and doc["labels_dropped"] == {
        "DontCare": 6}
    for fid, (boxes, pts) in truth.items():
        f = ds.frame(fid)
        assert f.names == ("door", "door")                       # "Door" matched without case
        np.testing.assert_allclose(f.boxes[:, :6], boxes[:, :6], atol=1e-4)
        dh = (f.boxes[:, 6] - boxes[:, 6] + np.pi) % (2 * np.pi) - np.pi
        np.testing.assert_allclose(dh, 0.0, atol=1e-4)
        np.testing.assert_array_equal(f.points, pts[:, [0, 1, 2, 3, 5]])
        inside = points_in_boxes(f.points, f.boxes, margin_m=1e-3).any(axis=1)
        assert inside.all()                                     # every object point in its box
    meta = read_metadata(tmp_path / "out")
    assert meta["domain"] == "measured" and meta["points"]["num_point_features"] == 5
    # no test.txt in the source: half of val, seeded, and said
    assert len(ds.split_ids("val")) + len(ds.split_ids("test")) == 3
    assert ds.split_ids("test") and any("carved from val" in n for n in meta["notes"])


def test_other_classes_are_refused_up_front_naming_the_file_or_dropped_on_request(tmp_path):
    _kitti_source(tmp_path / "src", names=("Door", "Pedestrian"))
    with pytest.raises(DatasetError, match=r"label_2/000000.txt: label class 'Pedestrian' is "
                                           r"not one of the detector's classes \['door'\]"):
        import_dataset(tmp_path / "src", tmp_path / "out", ImportSettings(point_dims=7))
    assert not (tmp_path / "out").exists()                      # nothing written
    doc = import_dataset(tmp_path / "src", tmp_path / "out",
                         ImportSettings(point_dims=7, drop_other_classes=True))
    assert doc["labels"] == 6 and doc["labels_dropped"] == {"DontCare": 6, "Pedestrian": 6}


def test_kitti_labels_without_calibration_name_the_missing_file(tmp_path):
    _kitti_source(tmp_path / "src")
    (tmp_path / "src" / "calib" / "000002.txt").unlink()
    with pytest.raises(DatasetError, match=r"calib/000002.txt: KITTI labels are in the camera "
                                           r"frame"):
        import_dataset(tmp_path / "src", tmp_path / "out", ImportSettings(point_dims=7))
    assert read_kitti_calib.__doc__


def test_pcd_files_and_custom_labels_without_imagesets(tmp_path):
    from pypcd4 import PointCloud

    src = tmp_path / "src"
    (src / "points").mkdir(parents=True)
    (src / "labels").mkdir()
    rng = np.random.default_rng(0)
    for i in range(8):
        pts = rng.random((50, 4)).astype(np.float32) * [8, 4, 2, 30]
        pts[3] = np.nan                                          # a missing return
        PointCloud.from_xyzi_points(pts).save(src / "points" / f"seq1_{i:03d}.pcd")
        (src / "labels" / f"seq1_{i:03d}.txt").write_text("3 0.5 1 0.9 0.1 2 0.3 DOOR\n")
    doc = import_dataset(src, tmp_path / "out", ImportSettings(seed=4))
    ds = OpenPCDetDataset(tmp_path / "out")
    f = ds.frame("seq1_000")
    assert f.points.shape == (49, 4) and f.names == ("door",)
    np.testing.assert_allclose(f.boxes[0], [3, 0.5, 1, 0.9, 0.1, 2, 0.3], atol=1e-6)
    assert sum(doc["splits"].values()) == 8 and set(doc["splits"]) == {"train", "val", "test"}
    assert any("seeded 70/15/15" in n for n in doc["notes"])


def test_bin_files_need_their_row_width_and_errors_are_one_line(tmp_path):
    _kitti_source(tmp_path / "src", point_dims=7)
    with pytest.raises(DatasetError, match=r"000000.bin: \d+ float32 values are not rows of 6"):
        import_dataset(tmp_path / "src", tmp_path / "o6", ImportSettings(point_dims=6))
    res = CliRunner().invoke(app, ["import", str(tmp_path / "src"), "--out",
                                   str(tmp_path / "out")], env={"COLUMNS": "300"})
    assert res.exit_code == 2, res.output
    assert "a .bin file has no header" in res.output and "--point-dims" in res.output
    assert "Traceback" not in res.output
    res = CliRunner().invoke(app, ["import", str(tmp_path / "src"), "--out",
                                   str(tmp_path / "out"), "--point-dims", "7"],
                             env={"COLUMNS": "300"})
    assert res.exit_code == 0, res.output
    assert "imported 6 frames (4 point features, 12 labels of ['door']; dropped: DontCare 6)" \
        in " ".join(res.output.split())
    assert json.loads((tmp_path / "out" / "dataset.json").read_text())["labels"] == 12
