"""Bird's-eye-view (BEV) pictures of radar point clouds, boxes and the radar's field of view.

Pure functions over arrays: they return PNG bytes (and write them if given a path). Matplotlib
runs on its Agg backend through an explicit ``Figure`` — no pyplot global state, safe in worker
threads. A written PNG carries a digest of what it was drawn from (:data:`INPUTS_KEY`); asked to
draw the same picture to the same path again (a cached rerun of a dataset), :func:`bev_png`
returns that file and never imports Matplotlib (issue #23).

View convention: the radar frame is x forward, y left, z up. The picture looks down on it with
forward (+x) pointing up the page and left (+y) pointing left, as a driver would draw it.
"""

from __future__ import annotations

import hashlib
import io
import json
import struct
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from sim2radar.boxes import box_corners

__all__ = ["INPUTS_KEY", "bev_png", "box_corners_xy", "frames_bev_png", "radar_frames_pngs",
           "scene_extent"]

#: PNG text chunk holding the digest of a picture's inputs (and of :data:`_DRAWING_VERSION`).
INPUTS_KEY = "sim2radar-inputs"
#: Bump when :func:`bev_png` draws differently: pictures written before are then redrawn.
_DRAWING_VERSION = "1"
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def box_corners_xy(boxes: np.ndarray) -> np.ndarray:
    """(M, 4, 2) corner x, y [m] of boxes ``x y z dx dy dz heading`` (counter-clockwise)."""
    # bottom corners of sim2radar.boxes.box_corners: (+,+), (-,+), (-,-), (+,-) in (dx, dy)
    return box_corners(boxes)[:, [6, 2, 0, 4], :2]


def bev_png(
    points: np.ndarray,
    *,
    boxes: np.ndarray | None = None,
    box_labels: Sequence[str] | None = None,
    fov_deg: float | None = None,
    max_range_m: float | None = None,
    title: str = "",
    extent_m: tuple[float, float, float, float] | None = None,
    path: str | Path | None = None,
    size_px: int = 800,
) -> bytes:
    """Render a bird's-eye view of radar points as a PNG.

    Parameters
    ----------
    points : (N, 3+) float — x, y, z [m] in the radar frame, optional 4th column intensity [dB]
        (colour); without it points are drawn in one colour.
    boxes : (M, 7), optional — ``x y z dx dy dz heading`` [m, rad] in the radar frame.
    box_labels : M strings, optional — drawn next to each box.
    fov_deg : float, optional — full azimuth field of view [deg]; drawn as two rays from the radar.
    max_range_m : float, optional — drawn as an arc (with ``fov_deg``) [m].
    title : str — figure title.
    extent_m : (x_min, x_max, y_min, y_max), optional — view window [m]; default fits the
        points, boxes and the radar.
    path : str or Path, optional — also write the PNG there (parent folders are created).
    size_px : int — image height [px]; the width follows the view's aspect ratio.

    Returns
    -------
    bytes
        The PNG file content.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise ValueError(f"points must have shape (N, 3) or (N, 4), got {pts.shape}")
    bxs = np.zeros((0, 7)) if boxes is None else np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if box_labels is not None and len(box_labels) != len(bxs):
        raise ValueError(f"{len(box_labels)} box labels for {len(bxs)} boxes")
    digest = _inputs_digest(pts, bxs, box_labels, fov_deg, max_range_m, title, extent_m, size_px)
    if path is not None:
        drawn = _png_if_drawn_from(Path(path), digest)
        if drawn is not None:
            return drawn

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Polygon, Wedge

    if extent_m is None:
        xs = [0.0, *pts[:, 0], *box_corners_xy(bxs)[..., 0].ravel()]
        ys = [0.0, *pts[:, 1], *box_corners_xy(bxs)[..., 1].ravel()]
        pad = 0.5
        x0, x1 = min(xs) - pad, max(xs) + pad
        y0, y1 = min(ys) - pad, max(ys) + pad
    else:
        x0, x1, y0, y1 = extent_m

    dpi = 100
    # width follows the view's aspect (page width = y span, height = x span) + room for labels
    aspect = float(np.clip((y1 - y0) / max(x1 - x0, 1e-6), 0.5, 2.0))
    width_px = int(round(size_px * aspect)) + 200
    fig = Figure(figsize=(width_px / dpi, size_px / dpi), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    # page coordinates: horizontal = y (left is +y), vertical = x (forward is up)
    if fov_deg is not None:
        reach = max_range_m if max_range_m is not None else float(np.hypot(x1 - x0, y1 - y0))
        half = np.radians(fov_deg) / 2
        for sign in (-1, 1):
            ax.plot([0, sign * reach * np.sin(half)], [0, reach * np.cos(half)], color="0.6", lw=0.8, ls="--")
        if max_range_m is not None:
            # angles measured on the page: 90° is straight up (+x); +y is to the left
            ax.add_patch(
                Wedge((0, 0), max_range_m, 90 - np.degrees(half), 90 + np.degrees(half),
                      facecolor="0.9", edgecolor="0.6", lw=0.8, alpha=0.4, zorder=0)
            )
    for i, corners in enumerate(box_corners_xy(bxs)):
        ax.add_patch(Polygon(corners[:, ::-1], closed=True, fill=False, edgecolor="tab:red", lw=1.5))
        if box_labels is not None:
            ax.text(corners[:, 1].max(), corners[:, 0].max(), box_labels[i], color="tab:red", fontsize=8)
    if len(pts):
        if pts.shape[1] >= 4:
            sc = ax.scatter(pts[:, 1], pts[:, 0], c=pts[:, 3], s=6, cmap="viridis", linewidths=0)
            fig.colorbar(sc, ax=ax, fraction=0.046, pad=0.04, label="intensity [dB]")
        else:
            ax.scatter(pts[:, 1], pts[:, 0], s=6, color="tab:blue", linewidths=0)
    ax.plot([0], [0], marker="^", color="k", ms=8)
    ax.set_xlim(y1, y0)  # +y to the left
    ax.set_ylim(x0, x1)
    ax.set_aspect("equal")
    ax.set_xlabel("y (left) [m]")
    ax.set_ylabel("x (forward) [m]")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.set_title(title or f"{len(pts)} radar points", fontsize=10)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={INPUTS_KEY: digest})
    data = buf.getvalue()
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    return data


def _inputs_digest(pts: np.ndarray, bxs: np.ndarray, *settings) -> str:
    """SHA-256 (hex) of a picture's arrays, its other arguments and :data:`_DRAWING_VERSION`."""
    h = hashlib.sha256(f"bev_png {_DRAWING_VERSION}".encode())
    for a in (pts, bxs):
        h.update(f"{a.shape}".encode())
        h.update(np.ascontiguousarray(a).tobytes())
    labels, *rest = settings
    h.update(json.dumps([None if labels is None else [str(x) for x in labels], *rest],
                        default=lambda v: np.asarray(v).tolist()).encode())
    return h.hexdigest()


def _png_if_drawn_from(path: Path, digest: str) -> bytes | None:
    """The PNG at ``path`` if its :data:`INPUTS_KEY` text chunk is ``digest``, else None (no
    file, another picture, not a PNG)."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if not data.startswith(_PNG_SIGNATURE):
        return None
    pos, key = len(_PNG_SIGNATURE), INPUTS_KEY.encode("latin-1") + b"\0"
    while pos + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        if kind == b"tEXt" and body.startswith(key):
            return data if body[len(key):] == digest.encode("latin-1") else None
        if kind in (b"IDAT", b"IEND"):  # the text chunks come first
            return None
        pos += 12 + length
    return None


def frames_bev_png(frames: Sequence, path: str | Path, *, class_name: str = "door",
                   title: str = "") -> Path:
    """A bird's-eye view of a sequence of radar frames (``DatasetFrame``-like: ``points``,
    ``boxes``, ``gt_boxes``, ``radar_to_world``, ``geometry``): every frame's points and labels
    moved into the first frame's radar frame, ground-truth doors drawn as ``gt`` (left out for
    ``ground_truth`` frames, whose labels are those doors). Framed on the points and boxes
    with 1 m margin, the radar at the origin always in view."""
    from sim2radar.boxes import transform_boxes

    ref_inv = np.linalg.inv(frames[0].radar_to_world)
    pts, boxes, labels = [], [], []
    for df in frames:
        m = ref_inv @ df.radar_to_world
        p = np.asarray(df.points, np.float32).copy()
        p[:, :3] = p[:, :3] @ m[:3, :3].T + m[:3, 3]
        pts.append(p)
        for b, lab in ((df.boxes, class_name), (df.gt_boxes, "gt")):
            if len(b) and not (df.geometry == "ground_truth" and lab == "gt"):
                boxes.append(transform_boxes(b, m, period="full"))
                labels += [lab] * len(b)
    pts_all = np.concatenate(pts) if pts else np.zeros((0, 4), np.float32)
    box_all = np.concatenate(boxes) if boxes else np.zeros((0, 7), np.float32)
    bev_png(pts_all, boxes=box_all, box_labels=labels, extent_m=scene_extent(pts_all, box_all),
            title=f"{title}: {len(frames)} frames, {len(pts_all)} points", path=path)
    return Path(path)


def scene_extent(points: np.ndarray, boxes: np.ndarray, margin_m: float = 1.0
                 ) -> tuple[float, float, float, float]:
    """(x_min, x_max, y_min, y_max) [m] framing a picture on the scene rather than the radar's
    full range: the points' and box centres' x, y and the radar at the origin, plus
    ``margin_m``."""
    pts = np.asarray(points, np.float32)
    pts_xy = pts[:, :2] if pts.ndim == 2 else np.zeros((0, 2), np.float32)
    b = np.asarray(boxes, np.float32).reshape(-1, 7)
    xy = np.concatenate([pts_xy, b[:, :2], np.zeros((1, 2), np.float32)])
    lo, hi = xy.min(axis=0) - margin_m, xy.max(axis=0) + margin_m
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def radar_frames_pngs(frames: Sequence, png_dir: str | Path, *, radar=None,
                      scene_id: str | None = None) -> list[str]:
    """One bird's-eye-view PNG per radar frame (:class:`sim2radar.storage.codecs` radar frames:
    ``points``, ``boxes``, ``box_labels``, ``frame_index``, ``scene_id``), framed on the scene
    rather than the radar's full range, with ``radar``'s azimuth FOV drawn when given. Files
    are ``<scene_id>_f<frame>.png``; returns their paths."""
    fov = getattr(radar, "azimuth_fov_rad", None)
    max_range = getattr(radar, "max_range_m", None)
    fov_deg = float(np.degrees(fov)) if fov is not None else None
    out = []
    for f in frames:
        sid = scene_id or f.scene_id
        path = Path(png_dir) / f"{sid}_f{f.frame_index:03d}.png"
        extent = scene_extent(f.points, f.boxes) if len(f.points) or len(f.boxes) else None
        bev_png(f.points, boxes=f.boxes, box_labels=f.box_labels, fov_deg=fov_deg,
                max_range_m=None if extent is not None or max_range is None else float(max_range),
                extent_m=extent, title=f"{sid} frame {f.frame_index}: {len(f.points)} points",
                path=path)
        out.append(str(path))
    return out
