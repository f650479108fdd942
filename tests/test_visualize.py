"""BEV pictures: valid PNG, and geometry lands where the convention says (forward up, left left)."""

from __future__ import annotations

import io

import matplotlib.image as mpimg
import numpy as np
import pytest

from sim2radar.visualize import bev_png, box_corners_xy

EXTENT = (-1.0, 6.0, -3.5, 3.5)


def _ink_centroid(png: bytes) -> tuple[float, float]:
    """(row, col) centroid of strongly coloured (non-grey) pixels."""
    img = mpimg.imread(io.BytesIO(png))[..., :3]
    chroma = img.max(axis=2) - img.min(axis=2)
    rows, cols = np.nonzero(chroma > 0.35)
    return rows.mean(), cols.mean()


def test_png_is_written_and_decodes(tmp_path):
    pts = np.array([[3.0, 0.0, 0.0, 20.0], [4.0, 1.0, 0.5, 10.0]], np.float32)
    out = tmp_path / "sub" / "bev.png"
    data = bev_png(pts, boxes=[[3, 0, 1, 0.1, 1, 2, 0]], box_labels=["door"], fov_deg=120,
                   max_range_m=5, path=out, size_px=300)
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and out.read_bytes() == data
    assert mpimg.imread(io.BytesIO(data)).shape[0] == 300


def test_forward_is_up_and_left_is_left():
    # one colour-less box drawn in red, moved around in the radar frame
    def centroid(x, y):
        return _ink_centroid(bev_png(np.zeros((0, 3)), boxes=[[x, y, 0, 0.6, 0.6, 1, 0]], extent_m=EXTENT))

    near_row, _ = centroid(1.0, 0.0)
    far_row, _ = centroid(5.0, 0.0)
    assert far_row < near_row - 50  # farther forward = higher on the page
    _, left_col = centroid(3.0, 2.5)
    _, right_col = centroid(3.0, -2.5)
    assert left_col < right_col - 50  # +y (left) = left on the page


def test_box_corners_follow_heading():
    corners = box_corners_xy(np.array([[1.0, 2.0, 0, 2.0, 1.0, 1, np.pi / 2]]))[0]
    # rotated 90°: the 2 m side now runs along y
    assert np.ptp(corners[:, 1]) == pytest.approx(2.0) and np.ptp(corners[:, 0]) == pytest.approx(1.0)
    assert corners.mean(axis=0) == pytest.approx([1.0, 2.0])


def test_bad_input_is_named():
    with pytest.raises(ValueError, match=r"points must have shape"):
        bev_png(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="box labels"):
        bev_png(np.zeros((0, 3)), boxes=np.zeros((1, 7)) + 1, box_labels=[])


def test_scene_extent_frames_points_boxes_and_the_radar():
    import numpy as np

    from sim2radar.visualize import scene_extent

    pts = np.array([[2.0, -1.0, 0, 0], [5.0, 3.0, 0, 0]], np.float32)
    boxes = np.array([[7.0, 0.0, 1, 1, 0.2, 2, 0]], np.float32)
    assert scene_extent(pts, boxes) == (-1.0, 8.0, -2.0, 4.0)  # x from the radar at 0 to 7 + 1
    assert scene_extent(np.zeros((0, 4)), np.zeros((0, 7)), margin_m=0.5) == (-0.5, 0.5, -0.5, 0.5)


def test_the_same_picture_is_not_drawn_twice(tmp_path):
    """A cached rerun asks for the pictures it already wrote: the file is returned as it is
    (not rewritten, no Matplotlib); other inputs, or a PNG without the digest, are drawn."""
    import os

    pts = np.array([[3.0, 0.0, 0.0, 20.0], [4.0, 1.0, 0.5, 10.0]], np.float32)
    out = tmp_path / "bev.png"
    first = bev_png(pts, boxes=[[3, 0, 1, 0.1, 1, 2, 0]], box_labels=["door"], path=out,
                    size_px=200)
    os.utime(out, ns=(0, 0))
    again = bev_png(pts, boxes=[[3, 0, 1, 0.1, 1, 2, 0]], box_labels=["door"], path=out,
                    size_px=200)
    assert again == first and out.stat().st_mtime_ns == 0
    moved = bev_png(pts + 0.5, boxes=[[3, 0, 1, 0.1, 1, 2, 0]], box_labels=["door"], path=out,
                    size_px=200)
    assert moved != first and out.read_bytes() == moved
    relabelled = bev_png(pts + 0.5, boxes=[[3, 0, 1, 0.1, 1, 2, 0]], box_labels=["gt"],
                         path=out, size_px=200)
    assert relabelled != moved and out.read_bytes() == relabelled
    out.write_bytes(bev_png(pts, size_px=200)[:40])  # a truncated PNG without its text chunks
    redrawn = bev_png(pts, path=out, size_px=200)
    assert out.read_bytes() == redrawn and mpimg.imread(io.BytesIO(redrawn)).shape[0] == 200
