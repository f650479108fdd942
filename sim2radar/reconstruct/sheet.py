"""A PNG contact sheet of the reconstruction stages, like the paper's Figure 2.

Panels: (a) input RGB with the LiDAR points that fall in the image, (b) depth, (c) segments with
their labels, (d) materials, (e) the material-labelled 3D scene, (f) bird's-eye view with the
door boxes. Matplotlib with the Agg backend; a pure function of a :class:`LabeledScene`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim2radar.camera import project
from sim2radar.reconstruct.doors import box_corners
from sim2radar.vocab import MATERIAL_CLASSES

__all__ = ["MATERIAL_COLOURS", "stage_sheet"]

#: Display colour per material class (RGB in [0, 1]).
MATERIAL_COLOURS: dict[str, tuple[float, float, float]] = {
    "unknown": (0.0, 0.0, 0.0),
    "metal": (0.2, 0.4, 0.9),
    "glass": (0.5, 0.9, 0.95),
    "wood": (0.6, 0.35, 0.1),
    "plasterboard": (0.92, 0.9, 0.8),
    "ceramic_tile": (0.85, 0.4, 0.4),
    "concrete": (0.55, 0.55, 0.55),
    "fabric": (0.7, 0.3, 0.7),
    "plastic": (0.3, 0.8, 0.3),
}


def stage_sheet(scene, path: str | Path | None = None, *, lidar_points: np.ndarray | None = None,
                max_faces: int = 6000, dpi: int = 100):
    """Render the sheet; write it to ``path`` (PNG) if given and return the figure's RGB array.

    Parameters
    ----------
    scene : LabeledScene
    lidar_points : (N, 3) camera-frame LiDAR points to overlay on the input, optional.
    max_faces : int — faces drawn in the 3D panel (largest meshes first).

    Returns
    -------
    (H, W, 3) uint8 — the rendered sheet.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    fig = plt.figure(figsize=(15, 8.5), dpi=dpi)
    axes = [fig.add_subplot(2, 3, i + 1) for i in range(4)]
    ax3d = fig.add_subplot(2, 3, 5, projection="3d")
    axbev = fig.add_subplot(2, 3, 6)

    ax = axes[0]
    ax.imshow(scene.rgb)
    if lidar_points is not None and len(lidar_points):
        uv, ok = project(lidar_points, scene.intrinsics)
        ax.scatter(uv[ok, 0], uv[ok, 1], s=1, c=np.asarray(lidar_points)[ok, 2], cmap="turbo")
        ax.set_xlim(0, scene.intrinsics.width)
        ax.set_ylim(scene.intrinsics.height, 0)
    ax.set_title(f"(a) input: {scene.name}" + (" + LiDAR" if lidar_points is not None else ""))

    ax = axes[1]
    d = np.where(scene.depth_m > 0, scene.depth_m, np.nan)
    im = ax.imshow(d, cmap="turbo")
    fig.colorbar(im, ax=ax, fraction=0.035, label="depth [m]")
    ax.set_title("(b) depth")

    ax = axes[2]
    rng = np.random.default_rng(0)
    palette = rng.uniform(0.2, 1.0, (max(scene.n_segments, 1) + 1, 3))
    palette[-1] = 0
    seg_img = palette[scene.segment_id]
    ax.imshow(0.6 * seg_img + 0.4 * scene.rgb / 255.0)
    for k, label in enumerate(scene.segment_labels):
        ij = np.argwhere(scene.segment_id == k)
        if len(ij) > 0.002 * scene.segment_id.size:
            r, c = np.median(ij, axis=0)
            ax.text(c, r, label, fontsize=7, ha="center", va="center",
                    bbox={"facecolor": "white", "alpha": 0.6, "pad": 1, "lw": 0})
    ax.set_title(f"(c) segments ({scene.n_segments})")

    ax = axes[3]
    lut = np.array([MATERIAL_COLOURS[m] for m in MATERIAL_CLASSES])
    ax.imshow(lut[scene.material_id] * np.where(scene.segment_id >= 0, 1.0, 0.0)[..., None])
    present = [MATERIAL_CLASSES[i] for i in np.unique(scene.material_id) if i > 0]
    handles = [plt.Rectangle((0, 0), 1, 1, color=MATERIAL_COLOURS[m]) for m in present]
    ax.legend(handles, present, fontsize=7, loc="lower right", framealpha=0.7)
    ax.set_title("(d) materials")
    for a in axes:
        a.set_xticks([])
        a.set_yticks([])

    # (e) 3D scene in the level frame (x forward, y left, z up)
    meshes = sorted(scene.meshes_in(None), key=lambda m: -len(m.faces))
    budget = max_faces
    for m in meshes:
        if budget <= 0:
            break
        tris = m.triangles[:budget]
        budget -= len(tris)
        ax3d.add_collection3d(Poly3DCollection(tris, facecolor=MATERIAL_COLOURS.get(m.material, (0, 0, 0)),
                                               edgecolor="none", alpha=0.85))
    pts = scene.points_in(None)
    if len(pts):
        lo, hi = np.percentile(pts, [1, 99], axis=0)
        ax3d.set_xlim(0, hi[0])
        ax3d.set_ylim(lo[1], hi[1])
        ax3d.set_zlim(lo[2], hi[2])
    for box in scene.door_boxes:
        c = box_corners(box)
        for i, j in ((0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7),
                     (0, 4), (1, 5), (2, 6), (3, 7)):
            ax3d.plot(*zip(c[i], c[j], strict=True), color="red", lw=1)
    ax3d.view_init(elev=25, azim=-160)
    ax3d.set_xlabel("x [m]")
    ax3d.set_ylabel("y [m]")
    ax3d.set_zlabel("z [m]")
    ax3d.set_title("(e) 3D scene (materials, door boxes)")

    # (f) bird's-eye view with door boxes
    if len(pts):
        sel = pts[:: max(1, len(pts) // 20000)]
        axbev.scatter(sel[:, 1], sel[:, 0], s=0.3, c=sel[:, 2], cmap="viridis")
    for box in scene.door_boxes:
        c = box_corners(box)[[0, 2, 6, 4, 0]]
        axbev.plot(c[:, 1], c[:, 0], color="red", lw=1.5)
    axbev.set_xlabel("y (left) [m]")
    axbev.set_ylabel("x (forward) [m]")
    axbev.invert_xaxis()
    axbev.set_aspect("equal", adjustable="datalim")
    axbev.set_title(f"(f) bird's-eye view, {len(scene.door_boxes)} door box(es)")

    fig.tight_layout()
    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path)
    plt.close(fig)
    return img
