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
    with pytest.raises(ValueError, match="radar_from_camera must be a 4x4"):
        read_radar_yaml(scenes[0].radar)
