"""Stage 4d: what a fitted door box physically returns — a door template in the wall.

A reconstructed door is the mesh of its pixels: a flat leaf (or the dark opening beyond it).
What the radar sees of a real door is mostly elsewhere: the casing's steps against the wall
(small dihedrals), the metal lever handles and the hinge knuckles (cylinders that return over
a wide arc; :mod:`sim2radar.door_parts`). Monocular depth never resolves them, so the paper's
pipeline (arXiv 2602.13314) loses them. This stage puts them back where every door has them,
from the fitted doorway box (:mod:`sim2radar.reconstruct.doors`) alone:

* **casing**: jambs and head around the box's outline on the wall face toward the camera,
  ``casing_width_m`` wide, standing ``casing_depth_m`` proud of the wall (the procedural
  worlds' frame: 6 cm wide, 1 cm proud);
* **handle**: a lever (spindle + grip, :func:`sim2radar.door_parts.lever_handle_parts`) on the
  leaf face seen, near the box's ``-dx`` end (the latch side is not known from one image; the
  template takes one, consistently);
* **hinges**: knuckles (:func:`sim2radar.door_parts.hinge_parts`) on the hinge line at the box's
  ``+dx`` end, on the same face.

The leaf face is where the door's own pixels are (the median depth, across the wall, of the
reconstructed points inside the box), else the box's face toward the camera. Everything is in
the level frame (x forward, y left, z up at the camera), where the box lives; the pipeline moves
the meshes to the camera frame like every other mesh. ``DoorTemplateConfig.enabled: false``
gives the paper's pipeline (no template).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sim2radar.door_parts import DoorHardware, casing_parts, hinge_parts, lever_handle_parts
from sim2radar.mesh import MaterialMesh

__all__ = ["DoorTemplateConfig", "door_template_meshes"]


@dataclasses.dataclass(frozen=True)
class DoorTemplateConfig:
    """Options of the door template.

    Attributes
    ----------
    enabled : bool — add the template (False: the paper's pipeline, door pixels only).
    casing_width_m, casing_depth_m : float [m] — the casing's face width and how far it stands
        proud of the wall (the procedural worlds' door frame: 0.06 m and 0.01 m; common
        architraves 50-70 mm x 15-25 mm).
    casing_material, hardware_material : str — materials of the casing and of handle and
        hinges (the procedural worlds' priors: door frames 80 % metal, handles metal; a
        measured frame material replaces them when the label names one).
    leaf_search_m : float [m] — reconstructed points within this of the box (grown on every
        side) place the leaf face.
    """

    enabled: bool = True
    casing_width_m: float = 0.06
    casing_depth_m: float = 0.01
    casing_material: str = "metal"
    hardware_material: str = "metal"
    leaf_search_m: float = 0.1


def _leaf_face(box: np.ndarray, points_level: np.ndarray | None, search_m: float) -> float:
    """Across-wall coordinate [m] (box frame, 0 = the box's centre plane) of the leaf face
    seen: the median of the reconstructed points inside the grown box; NaN without any."""
    if points_level is None or not len(points_level):
        return math.nan
    c, s = math.cos(float(box[6])), math.sin(float(box[6]))
    d = np.asarray(points_level, np.float64)[:, :3] - box[:3]
    along = d[:, 0] * c + d[:, 1] * s
    across = -d[:, 0] * s + d[:, 1] * c
    inside = ((np.abs(along) <= box[3] / 2 + search_m) & (np.abs(across) <= box[4] / 2 + search_m)
              & (np.abs(d[:, 2]) <= box[5] / 2 + search_m))
    return float(np.median(across[inside])) if inside.sum() >= 10 else math.nan


def door_template_meshes(boxes_level: np.ndarray, points_level: np.ndarray | None = None,
                         floor_z_m: float | None = None,
                         config: DoorTemplateConfig = DoorTemplateConfig(),
                         hardware: DoorHardware = DoorHardware()) -> list[MaterialMesh]:
    """The template's meshes for every door box (level frame, camera at the origin).

    Parameters
    ----------
    boxes_level : (M, 7) ``x y z dx dy dz heading`` [m, rad] — doorway boxes.
    points_level : (N, 3), optional — the door's reconstructed points (level frame) [m]: they
        place the leaf face.
    floor_z_m : float, optional [m] — the floor's height (the box's bottom otherwise): the
        handle and hinges are measured up from it.

    Returns
    -------
    list of MaterialMesh — per box ``door_template_{i}_casing`` and ``..._hardware``, semantic
    ``door``, level frame.
    """
    if not config.enabled:
        return []
    out = []
    for i, b in enumerate(np.asarray(boxes_level, np.float64).reshape(-1, 7)):
        c, s = math.cos(b[6]), math.sin(b[6])
        u_axis, v_axis = np.array([c, s, 0.0]), np.array([-s, c, 0.0])
        # the box's local frame: u along the wall, v across it toward the camera's side
        toward = -1.0 if float(np.dot(-b[:3], v_axis)) < 0 else 1.0
        v_axis = v_axis * toward
        floor = b[2] - b[5] / 2 if floor_z_m is None or not math.isfinite(floor_z_m) else floor_z_m
        origin = np.array([b[0], b[1], floor])
        height = b[2] + b[5] / 2 - floor
        wall_face = b[4] / 2                                    # the near face, v > 0
        leaf = _leaf_face(b, points_level, config.leaf_search_m) * toward
        leaf = leaf if math.isfinite(leaf) else wall_face
        casing = casing_parts(b[3], height, wall_face, config.casing_depth_m,
                              config.casing_width_m, toward=1)
        inner = b[3] / 2 - config.casing_width_m               # the opening's half-width
        hardware_parts = (
            lever_handle_parts((-inner, leaf - 0.02), (-1.0, 0.0), (0.0, 1.0), 0.04, hardware,
                               sides=(1,))
            + hinge_parts((inner, leaf), height, hardware))
        to_level = np.stack([u_axis, v_axis, np.array([0.0, 0.0, 1.0])], axis=1)
        out.append(_mesh(casing, to_level, origin, config.casing_material,
                         f"door_template_{i}_casing"))
        out.append(_mesh(hardware_parts, to_level, origin, config.hardware_material,
                         f"door_template_{i}_hardware"))
    return out


def _mesh(parts, to_level: np.ndarray, origin: np.ndarray, material: str,
          name: str) -> MaterialMesh:
    """One door mesh of local-frame parts: ``to_level`` (3, 3) columns u, v, z; ``origin`` [m]."""
    verts, faces, off = [], [], 0
    for v, f in parts:
        verts.append(v @ to_level.T + origin)
        faces.append(f + off)
        off += len(v)
    return MaterialMesh(np.concatenate(verts), np.concatenate(faces), material, name=name,
                        semantic="door")
