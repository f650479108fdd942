"""Synthetic indoor scenes for the radar benchmark and tests (no file I/O).

``corridor(target_triangles)`` builds a straight corridor in the radar frame (radar at the
origin looking down +x, mounted 1 m above the floor): finely subdivided concrete floor,
plasterboard walls and ceiling board, with doors, glass panels, metal extinguishers,
handrails and clutter. Subdivision is chosen so the total is close to ``target_triangles``.
"""

from __future__ import annotations

import math

import numpy as np

from sim2radar.mesh import MaterialMesh, box_mesh

__all__ = ["grid_plane", "corridor"]


def grid_plane(
    origin: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    nu: int,
    nv: int,
    *,
    material: str,
    name: str = "",
    semantic: str = "",
    flip: bool = False,
) -> MaterialMesh:
    """A parallelogram ``origin + s u + t v`` (s, t in [0, 1]) split into ``2 nu nv`` triangles.

    The normal is ``u x v`` (``-u x v`` with ``flip``).
    """
    origin, u, v = (np.asarray(a, dtype=np.float64) for a in (origin, u, v))
    s = np.linspace(0.0, 1.0, nu + 1)
    t = np.linspace(0.0, 1.0, nv + 1)
    ss, tt = np.meshgrid(s, t, indexing="ij")
    verts = origin + ss.reshape(-1, 1) * u + tt.reshape(-1, 1) * v
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = (i * (nv + 1) + j).ravel()
    b = a + (nv + 1)
    faces = np.concatenate([np.stack([a, b, b + 1], 1), np.stack([a, b + 1, a + 1], 1)])
    if flip:
        faces = faces[:, ::-1]
    return MaterialMesh(verts, faces, material=material, name=name, semantic=semantic)


def corridor(
    target_triangles: int = 100_000,
    *,
    length_m: float = 12.0,
    width_m: float = 2.4,
    height_m: float = 2.7,
    radar_height_m: float = 1.0,
) -> list[MaterialMesh]:
    """A corridor scene in the radar frame, about ``target_triangles`` triangles.

    Returns
    -------
    list of MaterialMesh — floor, ceiling, two walls, end wall, doors, glass, clutter.
    """
    x0, x1 = -0.5, length_m
    y_l, y_r = width_m / 2, -width_m / 2
    z_f, z_c = -radar_height_m, height_m - radar_height_m
    # share the budget between the 4 long surfaces (~96 %) and the details
    area = 2 * (x1 - x0) * width_m + 2 * (x1 - x0) * height_m
    cell = math.sqrt(area * 2 / (0.96 * target_triangles))  # triangle pairs per m^2
    n_len = max(1, round((x1 - x0) / cell))
    n_w = max(1, round(width_m / cell))
    n_h = max(1, round(height_m / cell))
    ex, ey, ez = np.eye(3)
    L = x1 - x0
    meshes = [
        grid_plane(
            [x0, y_r, z_f],
            L * ex,
            width_m * ey,
            n_len,
            n_w,
            material="concrete",
            name="floor",
            semantic="floor",
        ),
        grid_plane(
            [x0, y_r, z_c],
            L * ex,
            width_m * ey,
            n_len,
            n_w,
            material="ceiling_board",
            name="ceiling",
            semantic="ceiling",
            flip=True,
        ),
        grid_plane(
            [x0, y_l, z_f],
            L * ex,
            height_m * ez,
            n_len,
            n_h,
            material="plasterboard",
            name="wall_left",
            semantic="wall",
            flip=True,
        ),
        grid_plane(
            [x0, y_r, z_f],
            L * ex,
            height_m * ez,
            n_len,
            n_h,
            material="concrete",
            name="wall_right",
            semantic="wall",
        ),
        grid_plane(
            [x1, y_r, z_f],
            width_m * ey,
            height_m * ez,
            n_w,
            n_h,
            material="brick",
            name="end_wall",
            semantic="wall",
            flip=True,
        ),
    ]
    # doors: slightly proud of the walls, alternating sides and materials
    for k, xd in enumerate(np.arange(2.0, x1 - 1.0, 2.5)):
        side = 1 if k % 2 == 0 else -1
        yd = side * (width_m / 2 - 0.03)
        mat = ("wood", "metal", "glass")[k % 3]
        meshes.append(
            box_mesh(
                [xd, yd, z_f + 1.05],
                [0.95, 0.04, 2.1],
                material=mat,
                name=f"door_{k}",
                semantic="door",
            )
        )
        meshes.append(
            box_mesh(
                [xd + 0.52, yd, z_f + 1.05],
                [0.05, 0.07, 2.1],
                material="metal",
                name=f"door_frame_{k}",
                semantic="door",
            )
        )
    # clutter: extinguishers (metal), a cabinet (wood), a bin (plastic), handrail (metal)
    for k, xe in enumerate((3.2, 8.1)):
        meshes.append(
            box_mesh(
                [xe, y_r + 0.12, z_f + 0.45],
                [0.16, 0.16, 0.5],
                material="metal",
                name=f"extinguisher_{k}",
                semantic="fire_extinguisher",
            )
        )
    meshes.append(
        box_mesh(
            [5.5, y_l - 0.25, z_f + 0.6],
            [0.9, 0.45, 1.2],
            material="wood",
            name="cabinet",
            semantic="clutter",
        )
    )
    meshes.append(
        box_mesh(
            [6.8, y_r + 0.2, z_f + 0.3],
            [0.35, 0.35, 0.6],
            material="plastic",
            name="bin",
            semantic="clutter",
        )
    )
    meshes.append(
        box_mesh(
            [(x0 + x1) / 2, y_l - 0.06, z_f + 0.9],
            [L * 0.8, 0.04, 0.04],
            material="metal",
            name="handrail",
            semantic="handrail",
        )
    )
    return meshes
