"""Capture folders, radar poses in the reconstructed free space, the capture spec."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from sim2radar.factory.captures import (
    CaptureScene,
    CaptureSpec,
    PoseSampling,
    find_captures,
    free_space_mask,
    load_capture_frame,
    radar_mount,
    read_radar_yaml,
    rig_pose,
    rigid_transform,
    sample_radar_poses,
)

WALL_X_M = 3.0


def wall_ahead(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """First-hit distances to an infinite wall at x = 3 m (level frame)."""
    o, d = np.asarray(origins, float), np.asarray(directions, float)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (WALL_X_M - o[:, 0]) / d[:, 0]
    return np.where((d[:, 0] > 1e-9) & (t >= 0), t, np.inf)


def test_free_space_rejects_radars_in_or_behind_a_wall_and_outside_the_view():
    pos = np.array([[1.0, 0.0, 0.0],     # free, 2 m before the wall
                    [2.8, 0.0, 0.0],     # 0.2 m from the wall < clearance 0.3
                    [3.5, 0.0, 0.0],     # behind the wall: not seen by the camera
                    [1.0, 2.0, 0.0],     # 63 deg to the side, camera hfov 60 deg
                    [0.0, 0.0, 0.0]])    # the capture pose itself
    ok = free_space_mask(pos, wall_ahead, hfov_deg=60.0, clearance_m=0.3)
    assert ok.tolist() == [True, False, False, False, True]
    # without clearance the radar may stand 0.2 m from the wall, still not behind it
    ok0 = free_space_mask(pos, wall_ahead, hfov_deg=60.0, clearance_m=0.0)
    assert ok0.tolist() == [True, True, False, False, True]


def test_sampled_poses_are_deterministic_in_free_space_and_start_at_the_capture_pose():
    cfg = PoseSampling(frames=12, forward_m=(0.0, 4.0), lateral_m=(-1.0, 1.0), yaw_deg=(-30, 30))
    a, info = sample_radar_poses(np.eye(4), wall_ahead, cfg, hfov_deg=90.0, seed=5)
    b, _ = sample_radar_poses(np.eye(4), wall_ahead, cfg, hfov_deg=90.0, seed=5)
    c, _ = sample_radar_poses(np.eye(4), wall_ahead, cfg, hfov_deg=90.0, seed=6)
    assert a.shape == (12, 4, 4) and np.array_equal(a, b) and not np.array_equal(a, c)
    np.testing.assert_allclose(a[0], np.eye(4))
    assert info["rejected"] > 0  # the forward range reaches past the wall
    x = a[1:, 0, 3]
    assert (x <= WALL_X_M - cfg.clearance_m + 1e-9).all() and (x > 0).all()
    # every pose is a rigid transform turned about z only
    for p in a:
        np.testing.assert_allclose(p[:3, :3] @ p[:3, :3].T, np.eye(3), atol=1e-12)
        assert p[2, 2] == pytest.approx(1.0)


def test_given_poses_go_through_the_mount_and_the_free_space_check():
    mount = rig_pose(0.1, -0.05, 0.0, 0.2)  # radar 10 cm ahead, 5 cm right, 20 cm up
    given = np.array([[1.0, 0.0, 0.0], [5.0, 0.0, 0.0], [2.0, 0.0, 90.0]])
    poses, info = sample_radar_poses(mount, wall_ahead, PoseSampling(), hfov_deg=90.0, seed=0,
                                     given=given)
    assert info["wanted"] == 3 and len(poses) == 2  # 5 m is behind the wall
    np.testing.assert_allclose(poses[0][:3, 3], [1.1, -0.05, 0.2])
    # turned 90 deg left, the mount's 10 cm forward offset points along +y
    np.testing.assert_allclose(poses[1][:3, 3], [2.05, 0.1, 0.2], atol=1e-12)


def test_radar_mount_from_an_extrinsic():
    level_from_cam = np.array([[0, 0, 1, 0], [-1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 0, 1.0]])
    assert np.array_equal(radar_mount(level_from_cam, None), np.eye(4))
    # a level radar 0.1 m left of the camera: radar_from_camera = level_from_camera shifted
    radar_from_cam = level_from_cam.copy()
    radar_from_cam[1, 3] = -0.1
    np.testing.assert_allclose(radar_mount(level_from_cam, radar_from_cam)[:3, 3], [0, 0.1, 0])


def test_pose_sampling_and_spec_validation():
    with pytest.raises(ValueError, match="min <= max"):
        PoseSampling(forward_m=(2.0, 1.0))
    with pytest.raises(ValueError, match="oracle"):
        CaptureSpec(radar="ti-mmwcas", reconstruction="oracle")
    with pytest.raises(ValueError, match="class_name"):
        CaptureSpec(radar="ti-mmwcas", reconstruction=None, class_name="two words")
    spec = CaptureSpec(radar="ti-mmwcas", reconstruction=None, poses={"frames": 3})
    assert spec.poses.frames == 3 and spec.geometries == ("reconstructed",)
    assert spec.view[2] == pytest.approx(spec.radar.max_range_m)


def test_capture_folder_layout_and_errors_name_the_file(tmp_path):
    with pytest.raises(ValueError, match="capture folder not found"):
        find_captures(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no scene folders"):
        find_captures(tmp_path / "empty")
    root = tmp_path / "caps"
    (root / "a").mkdir(parents=True)
    (root / "b").mkdir()
    (root / "notes").mkdir()  # neither image nor intrinsics: not a scene
    k = {"fx": 100.0, "fy": 100.0, "cx": 16.0, "cy": 12.0, "width": 32, "height": 24}
    (root / "intrinsics.yaml").write_text(yaml.safe_dump(k))  # shared
    import cv2

    cv2.imwrite(str(root / "a" / "rgb.png"), np.full((24, 32, 3), 128, np.uint8))
    (root / "b" / "image.jpg").write_bytes(b"not a jpeg")
    (root / "a" / "radar.yaml").write_text(yaml.safe_dump({"poses": [[0.5, 0.0, 10.0]]}))
    scenes = find_captures(root)
    assert [s.scene_id for s in scenes] == ["a", "b"]
    assert scenes[0].intrinsics == str(root / "intrinsics.yaml")
    frame, note = load_capture_frame(scenes[0])
    assert frame.rgb.shape == (24, 32, 3) and frame.lidar_points is None and note == ""
    with pytest.raises(ValueError, match=r"b/image.jpg: not a readable image"):
        load_capture_frame(scenes[1])
    with pytest.raises(ValueError, match="no image; add rgb.png"):
        load_capture_frame(CaptureScene("c", str(root / "c"), None, str(root / "intrinsics.yaml")))
    assert read_radar_yaml(scenes[0].radar)["poses"].tolist() == [[0.5, 0.0, 10.0]]
    (root / "a" / "radar.yaml").write_text(yaml.safe_dump({"pose": [[0, 0, 0]]}))
    with pytest.raises(ValueError, match=r"radar.yaml: unknown key\(s\) \['pose'\]"):
        read_radar_yaml(scenes[0].radar)
    (root / "a" / "radar.yaml").write_text(yaml.safe_dump({"radar_from_camera": [[1, 0], [0, 1]]}))
    with pytest.raises(ValueError, match=r"radar_from_camera has shape \(2, 2\), expected"):
        read_radar_yaml(scenes[0].radar)


# --- issue #24: radar.yaml's radar_from_camera must be rigid, checked when the file is read ---
def _extrinsic(yaw_deg: float = 30.0, t=(0.1, -0.05, 0.2)) -> np.ndarray:
    """A camera (OpenCV) -> radar rigid transform: the axis swap, a turn, an offset [m]."""
    swap = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], float)  # x fwd = z cam, y left = -x
    m = rig_pose(0.0, 0.0, yaw_deg)
    m[:3, :3] = m[:3, :3] @ swap
    m[:3, 3] = t
    return m


@pytest.mark.parametrize("case, matrix, why", [
    ("singular", np.diag([1.0, 1.0, 0.0, 1.0]), "rotation part is singular (det 0)"),
    ("scaled", np.diag([1.1, 1.1, 1.1, 1.0]), "not orthonormal (max |R^T R - I| = 0.21"),
    ("sheared", np.array([[1, 0.01, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
     "not orthonormal"),
    ("mirrored", np.diag([1.0, -1.0, 1.0, 1.0]), "a reflection (det -1"),
    ("last row", np.vstack([np.eye(4)[:3], [0, 0, 1, 1]]),
     "last row [0.0, 0.0, 1.0, 1.0], expected [0, 0, 0, 1]"),
    ("NaN", np.where(np.eye(4) > 0, np.nan, 0.0), "holds NaN or infinite values"),
    ("text", [["a", 0, 0, 0]] * 4, "is not a 4x4 matrix of numbers"),
])
def test_a_radar_yaml_whose_extrinsic_is_not_rigid_is_refused_naming_file_field_and_fix(
        tmp_path, case, matrix, why):
    """The probe: a singular radar_from_camera gave `[poses] LinAlgError: Singular matrix`, a
    scaled one passed and failed every frame at simulate. Now reading the file refuses it in
    one line with the file, the field, what is wrong and the fix."""
    path = tmp_path / "radar.yaml"
    m = matrix.tolist() if isinstance(matrix, np.ndarray) else matrix
    path.write_text(yaml.safe_dump({"radar_from_camera": m}))
    with pytest.raises(ValueError) as info:
        read_radar_yaml(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: radar_from_camera ") and why in msg, msg
    assert "give radar_from_camera as a 4x4 rigid transform [R t; 0 0 0 1]" in msg
    assert "\n" not in msg


def test_a_rigid_extrinsic_printed_to_five_decimals_is_kept():
    m = _extrinsic()
    assert np.isclose(np.linalg.det(m[:3, :3]), 1.0)
    rounded = np.round(m, 5)
    got = rigid_transform(rounded.tolist(), "radar.yaml", "radar_from_camera")
    np.testing.assert_array_equal(got, rounded)
    # the radar's mount is then the exact rigid inverse: the camera seen from the radar
    mount = radar_mount(np.eye(4), got)
    np.testing.assert_allclose(mount[:3, :3].T @ mount[:3, :3], np.eye(3), atol=1e-4)


# --- issue #24: folders that are skipped, and symlinks out of the folder, are said ----------
def _scene(folder):
    import cv2

    folder.mkdir(parents=True)
    cv2.imwrite(str(folder / "rgb.png"), np.full((24, 32, 3), 128, np.uint8))
    k = {"fx": 100.0, "fy": 100.0, "cx": 16.0, "cy": 12.0, "width": 32, "height": 24}
    (folder / "intrinsics.yaml").write_text(yaml.safe_dump(k))
    return folder


def test_skipped_hidden_scene_folders_and_symlinks_out_are_one_warning_line_each(tmp_path, caplog):
    import logging

    root = tmp_path / "caps"
    _scene(root / "a")
    _scene(root / "...")  # the probe's folder: skipped, as hidden folders are, but said
    (root / ".git").mkdir()  # hidden and no scene files: skipped quietly
    elsewhere = _scene(tmp_path / "elsewhere" / "b")
    (root / "b").symlink_to(elsewhere, target_is_directory=True)
    _scene(root / "c")
    (root / "c" / "rgb.png").unlink()
    (root / "c" / "rgb.png").symlink_to(elsewhere / "rgb.png")
    (root / "d").symlink_to(tmp_path / "gone")  # a link to nothing
    (root / "e").symlink_to("a", target_is_directory=True)  # inside the folder: unremarkable
    with caplog.at_level(logging.WARNING, logger="sim2radar.factory.captures"):
        scenes = find_captures(root)
    assert [s.scene_id for s in scenes] == ["a", "b", "c", "e"]  # links still followed
    assert load_capture_frame(scenes[1])[0].rgb.shape == (24, 32, 3)
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 4 and all("\n" not in line for line in lines), lines
    assert lines[0].endswith("skipped folder '...': a name starting with '.' is hidden (like "
                             ".git); rename it without the leading dot to make it a scene")
    assert f"{root / 'b'} is a symlink to {elsewhere}, outside the capture folder; " \
           "following it" in lines[1]
    assert f"{root / 'c' / 'rgb.png'} is a symlink to {elsewhere / 'rgb.png'}" in lines[2]
    assert f"skipped 'd': a symlink to {tmp_path / 'gone'}, which does not exist" in lines[3]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="sim2radar.factory.captures"):
        assert len(find_captures(root, warn=False)) == 4
    assert caplog.records == []
    # only hidden scene folders: the error names them
    only = tmp_path / "only"
    _scene(only / "...")
    with pytest.raises(ValueError, match=r"no scene folders .*skipped hidden folder\(s\) \['...'\]"):
        find_captures(only, warn=False)
