"""Contact sheet of a rendered frame: RGB, depth, semantic and material maps, and a bird's-eye
view of the world with door boxes, the rig path and the radar's and camera's fields of view."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from sim2radar.vocab import MATERIAL_CLASSES, SEMANTIC_CLASSES
from sim2radar.worlds.config import RigConfig, radar_view
from sim2radar.worlds.frame import World, WorldFrame

__all__ = ["contact_sheet", "SEMANTIC_COLORS", "MATERIAL_COLORS"]

#: RGB colours in [0, 1] for semantic ids (index = id).
SEMANTIC_COLORS = np.array([
    (0, 0, 0), (0.75, 0.75, 0.70), (0.45, 0.35, 0.25), (0.55, 0.75, 0.90), (0.90, 0.15, 0.15),
    (0.30, 0.85, 0.95), (1.00, 0.55, 0.00), (0.65, 0.30, 0.85), (0.20, 0.65, 0.25),
])
#: RGB colours in [0, 1] for material ids (index = id).
MATERIAL_COLORS = np.array([
    (0, 0, 0), (0.35, 0.45, 0.85), (0.50, 0.95, 0.95), (0.65, 0.40, 0.15), (0.92, 0.90, 0.80),
    (0.90, 0.55, 0.55), (0.55, 0.55, 0.55), (0.75, 0.30, 0.65), (0.95, 0.85, 0.20),
])


def _bev(ax, world: World, frame: WorldFrame | None, rig: RigConfig) -> None:
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Polygon, Wedge

    for s in world.spaces:
        x0, x1, y0, y1 = s.rect_m
        ax.add_patch(Polygon([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], closed=True,
                             fc=(0.93, 0.93, 0.90), ec="none", zorder=0))
    for mesh, obj in zip(world.meshes, world.objects, strict=True):
        if obj.semantic in ("floor", "ceiling"):
            continue
        tri = mesh.triangles
        up = mesh.face_normals[:, 2] > 0.5
        if not up.any():
            continue
        color = SEMANTIC_COLORS[SEMANTIC_CLASSES.index(obj.semantic)]
        if obj.semantic == "wall":
            color = (0.25, 0.25, 0.25)
        ax.add_collection(PolyCollection(tri[up][:, :, :2], facecolors=[color],
                                         edgecolors="none", zorder=2))
    ax.plot(world.path_world[:, 0], world.path_world[:, 1], "--", color="0.5", lw=0.8, zorder=1)
    boxes = world.door_boxes_world
    visible = frame.door_visible if frame is not None else np.zeros(len(boxes), bool)
    in_fov = frame.door_in_fov & frame.door_in_range if frame is not None else visible
    for b, vis, fov in zip(boxes, visible, in_fov, strict=True):
        c, s = math.cos(b[6]), math.sin(b[6])
        hx, hy = b[3] / 2, b[4] / 2
        corners = [(b[0] + c * px - s * py, b[1] + s * px + c * py)
                   for px, py in ((-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy))]
        color = "red" if vis else ("orange" if fov else "0.4")
        ax.add_patch(Polygon(corners, closed=True, fill=False, ec=color, lw=1.4, zorder=4))
    if frame is not None:
        r = frame.radar_to_world
        yaw = math.degrees(math.atan2(r[1, 0], r[0, 0]))
        az_fov_deg, _, max_range_m = radar_view(rig)
        half = az_fov_deg / 2
        ax.add_patch(Wedge((r[0, 3], r[1, 3]), max_range_m, yaw - half, yaw + half,
                           fc=(0.2, 0.4, 1.0, 0.08), ec=(0.2, 0.4, 1.0, 0.6), lw=0.8, zorder=3))
        cw = frame.camera_to_world
        fwd = cw[:3, 2]
        cyaw = math.degrees(math.atan2(fwd[1], fwd[0]))
        ch = math.degrees(frame.intrinsics.hfov_rad) / 2
        ax.add_patch(Wedge((cw[0, 3], cw[1, 3]), 4.0, cyaw - ch, cyaw + ch,
                           fc=(0.1, 0.7, 0.1, 0.15), ec=(0.1, 0.6, 0.1, 0.8), lw=0.8, zorder=3))
        ax.plot([r[0, 3]], [r[1, 3]], "o", color="blue", ms=4, zorder=5)
    rects = np.array([s.rect_m for s in world.spaces])
    pad = 0.8
    ax.set_xlim(rects[:, 0].min() - pad, rects[:, 1].max() + pad)
    ax.set_ylim(rects[:, 2].min() - pad, rects[:, 3].max() + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"seed {world.seed}: {world.layout}, {len(world.doors)} doors "
                 "(red: visible, orange: in radar FOV)", fontsize=9)


def contact_sheet(world: World, frame: WorldFrame, path: str | Path,
                  rig: RigConfig | None = None) -> Path:
    """Write a PNG contact sheet (RGB, depth, semantic, material, bird's-eye view) to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    rig = rig or RigConfig()
    path = Path(path)
    fig = plt.figure(figsize=(16, 9), dpi=100)
    gs = fig.add_gridspec(2, 4, width_ratios=[1, 1, 1, 0.35])
    axes = [fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1]), fig.add_subplot(gs[0, 2]),
            fig.add_subplot(gs[1, 0]), fig.add_subplot(gs[1, 1:3])]
    axes[0].imshow(frame.rgb)
    axes[0].set_title(f"RGB (frame {frame.frame_index})", fontsize=9)
    d = np.where(frame.depth_m > 0, frame.depth_m, np.nan)
    im = axes[1].imshow(d, cmap="turbo")
    fig.colorbar(im, ax=axes[1], fraction=0.035, label="z-depth [m]")
    axes[1].set_title("depth", fontsize=9)
    axes[2].imshow(SEMANTIC_COLORS[frame.semantic_id])
    axes[2].set_title("semantic", fontsize=9)
    axes[3].imshow(MATERIAL_COLORS[frame.material_id])
    axes[3].set_title("material", fontsize=9)
    # project LiDAR points onto the depth panel
    from sim2radar.camera import project

    uv, ok = project(frame.lidar_points, frame.intrinsics)
    axes[1].scatter(uv[ok, 0], uv[ok, 1], s=0.3, c="white", alpha=0.6)
    for ax in axes[:4]:
        ax.set_xticks([])
        ax.set_yticks([])
    _bev(axes[4], world, frame, rig)
    leg = fig.add_subplot(gs[:, 3])
    leg.axis("off")
    sem = [Patch(color=SEMANTIC_COLORS[i], label=n) for i, n in enumerate(SEMANTIC_CLASSES) if i]
    mat = [Patch(color=MATERIAL_COLORS[i], label=n) for i, n in enumerate(MATERIAL_CLASSES) if i]
    l1 = leg.legend(handles=sem, title="semantic", loc="upper left", fontsize=8)
    leg.add_artist(l1)
    leg.legend(handles=mat, title="material", loc="lower left", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
