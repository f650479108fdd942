"""Tests for sim2radar/camera.py."""

import numpy as np
import pytest

from sim2radar.camera import CameraIntrinsics, back_project, project


def test_back_project_then_project_is_identity():
    k = CameraIntrinsics.from_fov(64, 48, 65.0)
    depth = np.full((48, 64), 3.0, dtype=np.float32)
    pts = back_project(depth, k)
    uv, valid = project(pts.reshape(-1, 3), k)
    assert valid.all()
    jj, ii = np.meshgrid(np.arange(64) + 0.5, np.arange(48) + 0.5)
    np.testing.assert_allclose(uv[:, 0], jj.ravel(), atol=1e-3)
    np.testing.assert_allclose(uv[:, 1], ii.ravel(), atol=1e-3)
    # the image edge ray makes half the horizontal FOV with the optical axis
    assert np.degrees(np.arctan2(pts[0, 0, 0] - (-0.0), 3.0)) == pytest.approx(-32.5, abs=0.6)


def test_invalid_intrinsics_name_the_field(tmp_path):
    with pytest.raises(ValueError, match="fx/fy"):
        CameraIntrinsics(-1, 1, 0, 0, 10, 10)
    p = tmp_path / "k.yaml"
    p.write_text("fx: 500\nfy: 500\ncx: 320\nwidth: 640\nheight: 480\n")
    with pytest.raises(ValueError, match="missing field 'cy'"):
        CameraIntrinsics.from_yaml(p)


GOOD_K = {"fx": "500", "fy": "500", "cx": "320", "cy": "240", "width": "640", "height": "480"}


@pytest.mark.parametrize("key, value, message", [
    ("cx", "[120.0]", "cx: must be a number [px], got [120.0]"),  # was a TypeError traceback
    ("fx", "five", "fx: must be a number [px], got 'five'"),
    ("width", "240.7", "width: must be a whole number, got 240.7"),  # was truncated to 240
    ("height", "true", "height: must be a whole number, got True"),
    ("K", "[[1, 2], [3]]", "K: must be a 3x3 matrix"),
])
def test_bad_intrinsics_values_name_file_field_and_fix(tmp_path, key, value, message):
    p = tmp_path / "k.yaml"
    p.write_text("".join(f"{k}: {v}\n" for k, v in {**GOOD_K, key: value}.items()))
    with pytest.raises(ValueError) as info:
        CameraIntrinsics.from_yaml(p)
    msg = str(info.value)
    assert msg.startswith(f"{p}: {message}") and "write e.g." in msg, msg


def test_whole_float_image_sizes_are_accepted(tmp_path):
    p = tmp_path / "k.yaml"
    p.write_text("".join(f"{k}: {v}\n" for k, v in {**GOOD_K, "width": "640.0"}.items()))
    k = CameraIntrinsics.from_yaml(p)
    assert k.width == 640 and isinstance(k.width, int) and k.cx == 320.0
