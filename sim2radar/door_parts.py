"""What a door has besides its leaf — hinge knuckles, lever handles, the casing around the
opening — as triangle parts in a door's local frame; shared by the procedural worlds
(:mod:`sim2radar.worlds.generate`) and the reconstruction's door template
(:mod:`sim2radar.reconstruct.door_template`).

A radar sees an indoor door through these parts more than through its leaf: the leaf is a flat
panel that sends its specular return back only when seen face-on, while a metal hinge knuckle or
lever is a cylinder that returns over a wide arc (broadside RCS ``2 pi a L^2 / lambda``,
Knott, *Radar Cross Section*, 2nd ed., Table 5.1) and the casing's step against the wall is a
small dihedral (RCS ``8 pi a^2 b^2 / lambda^2`` at its symmetry plane, ibid.); the tests check
the tracer against both closed forms (``tests/radar/test_door_features.py``).

Local frame (as :func:`sim2radar.worlds.generate.generate_world` builds doors): ``u`` along the
wall, ``v`` through the wall (positive toward the side the leaves swing to), ``z`` up from the
floor [m]. Every function returns a list of ``(vertices (V, 3) float64, faces (F, 3) int64)``
parts in that frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim2radar.mesh import box_mesh, cylinder_arrays

__all__ = ["DoorHardware", "casing_parts", "hinge_parts", "lever_handle_parts"]

Part = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class DoorHardware:
    """Sizes of a door's hardware [m]: typical building-hardware dimensions, not fitted to any
    radar result.

    Attributes
    ----------
    hinge_radius_m, hinge_length_m : a butt hinge's knuckle: 100 mm (4 in) hinges with a
        13-16 mm knuckle (EN 1935 grade hinges).
    hinge_heights_m : knuckle centres above the floor; the last is measured down from the
        leaf's top (``-0.25``: 0.25 m below it).
    handle_height_m : lever axis above the floor (DIN 18101: 1.05 m).
    lever_length_m, lever_radius_m : the lever's grip (EN 1906 lever handles: ~120-140 mm
        long, 18-20 mm thick).
    lever_projection_m : the grip's axis in front of the leaf face (the spindle's length:
        ~55-65 mm).
    spindle_radius_m : the spindle / rose neck carrying the lever.
    handle_inset_m : the spindle's distance from the leaf's free edge (a 60-70 mm backset).
    segments : flat facets of each cylinder. A facet about as wide as the cylinder's first
        Fresnel zone (``sqrt(lambda a / 2)``, ~4 mm for the lever at 77 GHz) returns like a
        small plate, not a cylinder: 16 facets read the lever's broadside RCS 2.7 dB high, 48
        (1.2 mm facets) within 0.5 dB (tests/radar/test_door_features.py).
    """

    hinge_radius_m: float = 0.007
    hinge_length_m: float = 0.10
    hinge_heights_m: tuple[float, ...] = (0.25, 1.05, -0.25)
    handle_height_m: float = 1.05
    lever_length_m: float = 0.13
    lever_radius_m: float = 0.0095
    lever_projection_m: float = 0.06
    spindle_radius_m: float = 0.008
    handle_inset_m: float = 0.065
    segments: int = 48


def hinge_parts(hinge_uv: Sequence[float], leaf_height_m: float,
                hw: DoorHardware = DoorHardware()) -> list[Part]:
    """Vertical knuckles on the hinge line ``hinge_uv`` ((u, v) [m]: where the leaf turns; the
    knuckles are centred on it and stay there whatever the leaf's angle)."""
    out = []
    for h in hw.hinge_heights_m:
        zc = h if h >= 0 else leaf_height_m + h
        base = (float(hinge_uv[0]), float(hinge_uv[1]), zc - hw.hinge_length_m / 2)
        out.append(cylinder_arrays(base, (0.0, 0.0, 1.0), hw.hinge_radius_m, hw.hinge_length_m,
                                   hw.segments))
    return out


def lever_handle_parts(free_edge_uv: Sequence[float], leaf_dir_uv: Sequence[float],
                       leaf_normal_uv: Sequence[float], leaf_thickness_m: float,
                       hw: DoorHardware = DoorHardware(), sides: Sequence[int] = (-1, 1)
                       ) -> list[Part]:
    """A lever handle on each face ``sides`` (+1: the face ``leaf_normal`` points to) of a leaf.

    Parameters
    ----------
    free_edge_uv : (u, v) [m] — the leaf's free (latch) edge at mid-thickness.
    leaf_dir_uv : unit (u, v) — from the hinge to the free edge (along the leaf).
    leaf_normal_uv : unit (u, v) — the leaf's face normal.
    leaf_thickness_m : [m].

    Each handle is a spindle from the face (``lever_projection_m`` long, along the normal) and a
    horizontal grip at its end, running from the spindle toward the hinge.
    """
    e = np.asarray(free_edge_uv, np.float64)
    d = np.asarray(leaf_dir_uv, np.float64) / np.linalg.norm(leaf_dir_uv)
    n = np.asarray(leaf_normal_uv, np.float64) / np.linalg.norm(leaf_normal_uv)
    z = hw.handle_height_m
    spindle_uv = e - d * hw.handle_inset_m
    out = []
    for side in sides:
        face = spindle_uv + side * n * leaf_thickness_m / 2
        out.append(cylinder_arrays((face[0], face[1], z), (side * n[0], side * n[1], 0.0),
                                   hw.spindle_radius_m, hw.lever_projection_m, hw.segments))
        grip = face + side * n * hw.lever_projection_m
        out.append(cylinder_arrays((grip[0], grip[1], z), (-d[0], -d[1], 0.0), hw.lever_radius_m,
                                   hw.lever_length_m, hw.segments))
    return out


def casing_parts(width_m: float, height_m: float, face_v_m: float, depth_m: float,
                 casing_width_m: float, toward: int = 1) -> list[Part]:
    """The casing (architrave) around an opening on one wall face: two jambs and a head,
    ``casing_width_m`` wide [m], standing ``depth_m`` proud of the wall face at
    ``v = face_v_m``, on the side ``toward`` (+1: +v); the opening spans ``u`` in
    ``[-width/2, width/2]`` (the casing's outer outline) and ``z`` in ``[0, height]``."""
    vc = face_v_m + toward * depth_m / 2
    w, h, cw = float(width_m), float(height_m), float(casing_width_m)
    boxes = [((-w / 2 + cw / 2, vc, h / 2), (cw, depth_m, h)),
             ((w / 2 - cw / 2, vc, h / 2), (cw, depth_m, h)),
             ((0.0, vc, h - cw / 2), (w - 2 * cw, depth_m, cw))]
    out = []
    for c, size in boxes:
        m = box_mesh(c, size, 0.0, material="metal")
        out.append((m.vertices.astype(np.float64), m.faces.astype(np.int64)))
    return out
