"""Seeded generation of IFR-like indoor worlds: corridors, side rooms, doors, windows, props.

One seed -> one world, byte-identical on every run (Kubric's rule): every random decision draws
from a named sub-stream ``np.random.default_rng([seed, stream])``, never from a global RNG, so
adding a draw to one stream (say, props) leaves the layout of every seed unchanged.

Construction
------------
1. Layout: a main corridor along +x (``straight``), with a perpendicular branch somewhere along it
   (``t_junction``) or at its far end (``l_turn``). Spaces are axis-aligned free rectangles.
2. Side rooms are placed along the corridors' long walls, separated from the corridor by one wall
   thickness, each with a single or double door; free wall stretches may get "blind" closed doors,
   dead ends may get an end door.
3. Walls are the cells of a ``grid_m`` raster within one wall thickness of free space (Chebyshev
   inflation of the rectangles), owned by the lowest-index space that reaches them (so a
   corridor/room wall is one material), minus door and window openings, merged into boxes.
4. Windows go where the raster shows open outside behind a wall; then fire extinguishers,
   clutter (cabinets, radiators, bins), handrails and ceiling light panels.
Every object draws one material from ``WorldConfig.material_priors`` and an appearance from
:mod:`sim2radar.worlds.appearance`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sim2radar.boxes import wrap_heading
from sim2radar.door_parts import hinge_parts, lever_handle_parts
from sim2radar.mesh import MaterialMesh
from sim2radar.vocab import MATERIAL_CLASSES, SEMANTIC_CLASSES
from sim2radar.worlds.appearance import sample_appearance
from sim2radar.worlds.config import CLUTTER_KINDS, DOOR_STATES, LAYOUTS, WorldConfig
from sim2radar.worlds.frame import Appearance, DoorSpec, Space, World, WorldObject
from sim2radar.worlds.geometry import (
    box_arrays,
    cylinder_arrays,
    greedy_rects,
    merge_arrays,
    yaw_matrix,
)

__all__ = ["generate_world", "STAGE_VERSION"]

#: Bump when generation changes what a seed produces (part of every artifact key).
STAGE_VERSION = 3  # 2: doorway door boxes; material-correlated textures; 3: door hardware
#                    (sim2radar.door_parts): lever handles on both faces, hinge knuckles

_STREAMS = {"layout": 1, "rooms": 2, "doors": 3, "materials": 4, "appearance": 5, "props": 6,
            "windows": 7, "lights": 8}
_EPS = 1e-6
_FLOOR_THICKNESS_M = 0.05


def _rng(seed: int, stream: str) -> np.random.Generator:
    return np.random.default_rng([seed, _STREAMS[stream]])


@dataclasses.dataclass
class _Side:
    """A wall face of a space: runs along ``axis`` from ``u0`` to ``u1`` at perpendicular
    coordinate ``coord``; ``inward`` (+1/-1) points from the face into the space."""

    space: int
    axis: str
    coord: float
    inward: int
    u0: float
    u1: float
    role: str  # "long" | "end" | "far"
    blocked: list = dataclasses.field(default_factory=list)  # (a, b, category)

    def point(self, s: float, d: float, z: float) -> np.ndarray:
        """World point at along-wall ``s``, distance ``d`` into the space, height ``z`` [m]."""
        p = self.coord + self.inward * d
        return np.array([s, p, z]) if self.axis == "x" else np.array([p, s, z])

    def behind_yaw(self) -> float:
        """Yaw [rad] of the direction from the space through the wall (the door swing side)."""
        if self.axis == "x":
            return -math.pi / 2 if self.inward > 0 else math.pi / 2
        return math.pi if self.inward > 0 else 0.0

    def free(self, a: float, b: float, categories: tuple[str, ...]) -> bool:
        if a < self.u0 - _EPS or b > self.u1 + _EPS:
            return False
        return all(b <= lo + _EPS or a >= hi - _EPS
                   for lo, hi, cat in self.blocked if cat in categories)

    @property
    def length(self) -> float:
        return self.u1 - self.u0


@dataclasses.dataclass
class _Obj:
    parts: list
    semantic: str
    material: str
    kind: str
    name: str
    door_index: int = -1
    space_index: int = -1
    appearance: Appearance | None = None


class _Raster:
    """A ``grid_m`` raster of the floor plan: free-space owner and wall owner per cell."""

    def __init__(self, spaces: list[Space], t: float, g: float, margin: float = 6.5):
        rects = np.array([s.rect_m for s in spaces])
        self.g = g
        self.ox = math.floor((rects[:, 0].min() - t - margin) / g) * g
        self.oy = math.floor((rects[:, 2].min() - t - margin) / g) * g
        nx = int(round((rects[:, 1].max() + t + margin - self.ox) / g))
        ny = int(round((rects[:, 3].max() + t + margin - self.oy) / g))
        self.free = np.full((nx, ny), -1, np.int16)
        self.wall = np.full((nx, ny), -1, np.int16)
        for s in spaces:
            self.free[self.sl(*s.rect_m)] = s.index
        for s in spaces:
            x0, x1, y0, y1 = s.rect_m
            sl = self.sl(x0 - t, x1 + t, y0 - t, y1 + t)
            take = (self.free[sl] < 0) & (self.wall[sl] < 0)
            self.wall[sl][take] = s.index
        self.opening = np.zeros((nx, ny), bool)

    def idx(self, x: float, y: float) -> tuple[int, int]:
        return int(round((x - self.ox) / self.g)), int(round((y - self.oy) / self.g))

    def sl(self, x0: float, x1: float, y0: float, y1: float) -> tuple[slice, slice]:
        i0, j0 = self.idx(x0, y0)
        i1, j1 = self.idx(x1, y1)
        return slice(max(i0, 0), max(i1, 0)), slice(max(j0, 0), max(j1, 0))

    def cell_rect(self, i0: int, i1: int, j0: int, j1: int) -> tuple[float, float, float, float]:
        g = self.g
        return self.ox + i0 * g, self.ox + i1 * g, self.oy + j0 * g, self.oy + j1 * g

    def void(self, x0: float, x1: float, y0: float, y1: float) -> bool:
        sl = self.sl(x0, x1, y0, y1)
        return bool((self.free[sl] < 0).all() and (self.wall[sl] < 0).all())


def _rect_of_band(side: _Side, a: float, b: float, d0: float, d1: float):
    """World rect (x0, x1, y0, y1) of along-wall [a, b] x inward distance [d0, d1]."""
    p0 = side.coord + side.inward * d0
    p1 = side.coord + side.inward * d1
    lo, hi = min(p0, p1), max(p0, p1)
    return (a, b, lo, hi) if side.axis == "x" else (lo, hi, a, b)


def _separation(r1, r2) -> float:
    gx = max(r1[0] - r2[1], r2[0] - r1[1])
    gy = max(r1[2] - r2[3], r2[2] - r1[3])
    return max(gx, gy)


def _choice(rng: np.random.Generator, table: dict[str, float]) -> str:
    keys = list(table)
    p = np.array([table[k] for k in keys], dtype=np.float64)
    return keys[int(rng.choice(len(keys), p=p / p.sum()))]


def generate_world(seed: int, config: WorldConfig | None = None) -> World:
    """Generate the world of ``seed``.

    Parameters
    ----------
    seed : int >= 0
    config : WorldConfig, optional — defaults to ``WorldConfig()``.

    Returns
    -------
    World — meshes in the world frame (z up, floor at z = 0), one object per mesh.
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    seed = int(seed)
    cfg = config if config is not None else WorldConfig()
    if not isinstance(cfg, WorldConfig):
        raise TypeError(f"config must be a WorldConfig, got {type(cfg).__name__}")
    g = cfg.grid_m

    def q(x: float) -> float:
        return round(x / g) * g

    def u(rng, lohi) -> float:
        return float(rng.uniform(*lohi))

    # ------------------------------------------------------------------ 1. layout
    r = _rng(seed, "layout")
    layout = _choice(r, cfg.layout_probs)
    length = q(u(r, cfg.corridor_length_m))
    width = q(u(r, cfg.corridor_width_m))
    height = q(u(r, cfg.ceiling_height_m))
    t = max(g, q(u(r, cfg.wall_thickness_m)))
    spaces: list[Space] = [Space(0, "corridor", (0.0, length, 0.0, width), "x")]
    path = [(0.6, width / 2)]
    junction = None
    if layout != "straight":
        bw = q(u(r, cfg.corridor_width_m))
        bl = q(u(r, cfg.branch_length_m))
        side = 1 if r.uniform() < 0.5 else -1
        if layout == "l_turn":
            xj = length - bw
        else:
            xj = q(r.uniform(2.0, max(2.0, length - 2.0 - bw)))
        y0, y1 = (width, width + bl) if side > 0 else (-bl, 0.0)
        spaces.append(Space(1, "corridor", (xj, xj + bw, y0, y1), "y"))
        junction = (xj, xj + bw, side)
        turn = layout == "l_turn" or r.uniform() < 0.5
        if turn:
            path.append((xj + bw / 2, width / 2))
            path.append((xj + bw / 2, (y1 - 0.6) if side > 0 else (y0 + 0.6)))
        else:
            path.append((length - 0.6, width / 2))
    else:
        path.append((length - 0.6, width / 2))

    # sides of corridors
    sides: list[_Side] = [
        _Side(0, "x", 0.0, +1, 0.0, length, "long"),
        _Side(0, "x", width, -1, 0.0, length, "long"),
        _Side(0, "y", 0.0, +1, 0.0, width, "end"),
    ]
    if layout != "l_turn":
        sides.append(_Side(0, "y", length, -1, 0.0, width, "end"))
    if junction is not None:
        xj0, xj1, side = junction
        main_side = sides[1] if side > 0 else sides[0]
        main_side.blocked.append((xj0, xj1, "opening"))
        bx0, bx1, by0, by1 = spaces[1].rect_m
        sides += [
            _Side(1, "y", bx0, +1, by0, by1, "long"),
            _Side(1, "y", bx1, -1, by0, by1, "long"),
        ]
        if side > 0:
            sides.append(_Side(1, "x", by1, -1, bx0, bx1, "end"))
        else:
            sides.append(_Side(1, "x", by0, +1, bx0, bx1, "end"))

    # ------------------------------------------------------------------ 2. rooms + doors
    rr = _rng(seed, "rooms")
    rd = _rng(seed, "doors")
    door_plans: list[dict] = []  # side, s0, s1 (opening), kind, leads_to

    def plan_door(side: _Side, s_center: float | None, a: float, b: float, leads_to: int,
                  allow_double: bool) -> bool:
        double = allow_double and rd.uniform() < cfg.door_double_probability
        clear = u(rd, cfg.door_double_width_m if double else cfg.door_single_width_m)
        ow = q(clear + 2 * cfg.door_frame_width_m)
        if b - a < ow + 0.2:
            if double:
                return plan_door(side, s_center, a, b, leads_to, False)
            return False
        # max(): b - a can fall short of ow + 0.2 by a rounding error (q() rounds ow); the
        # draw then has an empty range (seed 1161 raised "high - low < 0")
        s0 = (q(rd.uniform(a + 0.1, max(b - 0.1 - ow, a + 0.1))) if s_center is None
              else q(s_center - ow / 2))
        s0 = min(max(s0, q(a + 0.1)), q(b - 0.1 - ow))
        if not side.free(s0 - 0.1, s0 + ow + 0.1, ("opening", "door")):
            return False
        side.blocked.append((s0 - 0.15, s0 + ow + 0.15, "door"))
        door_plans.append(dict(side=side, s0=s0, s1=s0 + ow, double=double, leads_to=leads_to,
                               height=q(u(rd, cfg.door_height_m))))
        return True

    for side in [s for s in sides if s.role == "long"]:
        pos = side.u0 + q(rr.uniform(0.2, 1.5))
        while pos < side.u1 - 1.0:
            if rr.uniform() < cfg.room_probability:
                rw = q(u(rr, cfg.room_width_m))
                rdp = q(u(rr, cfg.room_depth_m))
                a, b = pos, min(pos + rw, side.u1 - 0.1)
                rect = _rect_of_band(side, a, b, -t, -t - rdp)
                ok = (b - a >= cfg.room_width_m[0] - _EPS
                      and side.free(a, b, ("opening",))
                      and all(_separation(rect, s.rect_m) >= t - _EPS for s in spaces))
                if ok and plan_door(side, None, a + 0.15, b - 0.15, len(spaces), True):
                    spaces.append(Space(len(spaces), "room", rect))
                    pos = b + t + q(u(rr, cfg.room_gap_m))
                    continue
            if rr.uniform() < cfg.blind_door_probability:
                plan_door(side, None, pos, min(pos + 1.6, side.u1), -1, False)
            pos += q(rr.uniform(1.0, 3.0))
    for side in [s for s in sides if s.role == "end"]:
        if rd.uniform() < cfg.end_door_probability:
            plan_door(side, (side.u0 + side.u1) / 2, side.u0, side.u1, -1, True)

    # room far walls (for windows and room props)
    for room in spaces[1:]:
        if room.kind != "room":
            continue
        door_side = next(p["side"] for p in door_plans if p["leads_to"] == room.index)
        x0, x1, y0, y1 = room.rect_m
        if door_side.axis == "x":
            far = (_Side(room.index, "x", y0, +1, x0, x1, "far") if door_side.inward > 0
                   else _Side(room.index, "x", y1, -1, x0, x1, "far"))
            lat = [_Side(room.index, "y", x0, +1, y0, y1, "lat"),
                   _Side(room.index, "y", x1, -1, y0, y1, "lat")]
        else:
            far = (_Side(room.index, "y", x0, +1, y0, y1, "far") if door_side.inward > 0
                   else _Side(room.index, "y", x1, -1, y0, y1, "far"))
            lat = [_Side(room.index, "x", y0, +1, x0, x1, "lat"),
                   _Side(room.index, "x", y1, -1, x0, x1, "lat")]
        # keep room props away from the door's swing zone (1.2 m from the door wall)
        for ls in lat:
            near = door_side.coord  # the door wall's face coordinate on the corridor side
            if abs(ls.u0 - near) < abs(ls.u1 - near):
                ls.blocked.append((ls.u0, ls.u0 + 1.3 + t, "door"))
            else:
                ls.blocked.append((ls.u1 - 1.3 - t, ls.u1, "door"))
        sides += [far, *lat]

    # ------------------------------------------------------------------ 3. raster + windows
    raster = _Raster(spaces, t, g)
    rw_ = _rng(seed, "windows")
    window_plans: list[dict] = []
    for side in sides:
        if side.role not in ("long", "far"):
            continue
        pos = side.u0 + 0.4
        while pos < side.u1 - 1.0:
            ww = q(u(rw_, cfg.window_width_m))
            place = rw_.uniform() < cfg.window_probability
            a, b = pos, pos + ww
            if place and b <= side.u1 - 0.3 and side.free(a - 0.2, b + 0.2, ("opening", "door")):
                behind = _rect_of_band(side, a - 0.3, b + 0.3, -t - g, -t - 6.0)
                if raster.void(*behind):
                    sill = q(u(rw_, cfg.window_sill_m))
                    top = q(u(rw_, cfg.window_top_m))
                    window_plans.append(dict(side=side, s0=a, s1=b, sill=min(sill, top - 0.3),
                                             top=top))
                    side.blocked.append((a - 0.1, b + 0.1, "window"))
                    pos = b + q(rw_.uniform(1.0, 3.0))
                    continue
            pos += q(rw_.uniform(1.5, 3.0))

    objs: list[_Obj] = []
    rm = _rng(seed, "materials")
    ra = _rng(seed, "appearance")

    def material_for(kind: str) -> str:
        return _choice(rm, cfg.material_priors[kind])

    def add(parts, semantic, kind, name, material=None, prior=None, door_index=-1,
            space_index=-1, appearance=None, emission=0.0) -> _Obj:
        mat = material or material_for(prior or kind)
        app = appearance or sample_appearance(mat, prior or kind, ra, emission=emission)
        obj = _Obj(list(parts), semantic, mat, kind, name, door_index, space_index, app)
        objs.append(obj)
        return obj

    # ------------------------------------------------------------------ 4. doors
    doors: list[DoorSpec] = []
    fw = cfg.door_frame_width_m
    lt = cfg.door_leaf_thickness_m
    lintels: dict[int, list] = {}
    thresholds: dict[int, list] = {}
    for k, plan in enumerate(door_plans):
        side: _Side = plan["side"]
        s0, s1, hd = plan["s0"], plan["s1"], plan["height"]
        ow = s1 - s0
        clear = ow - 2 * fw
        raster.opening[raster.sl(*_rect_of_band(side, s0, s1, 0.0, -t))] = True
        owner = side.space
        lintels.setdefault(owner, []).append(
            box_arrays(_center_of_band(side, s0, s1, 0.0, -t, hd + fw, height),
                       _size_of_band(side, s0, s1, t, height - hd - fw)))
        thresholds.setdefault(owner, []).append(
            box_arrays(_center_of_band(side, s0, s1, 0.0, -t, -_FLOOR_THICKNESS_M, 0.0),
                       _size_of_band(side, s0, s1, t, _FLOOR_THICKNESS_M)))
        if plan["leads_to"] < 0:
            # nothing is modelled behind a blind/end door: back it with a slab so no ray
            # escapes through the gaps around the leaf
            lintels[owner].append(
                box_arrays(_center_of_band(side, s0 - 0.05, s1 + 0.05, -t, -t - 0.05, 0.0, height),
                           _size_of_band(side, s0 - 0.05, s1 + 0.05, 0.05, height)))
        # local door frame: u along the wall, v through the wall towards the swing side, z up
        yaw_v = side.behind_yaw()
        yaw_u = yaw_v - math.pi / 2
        rot = yaw_matrix(yaw_u)
        origin = side.point((s0 + s1) / 2, -t / 2, 0.0)

        def to_world(parts, rot=rot, origin=origin):
            return [(v @ rot.T + origin, f) for v, f in parts]

        state = _choice(rd, cfg.door_state_probs) if plan["leads_to"] >= 0 else "closed"
        n_leaves = 2 if plan["double"] else 1
        if state == "closed":
            angles = (0.0,) * n_leaves
        else:
            lo_hi = cfg.ajar_deg if state == "ajar" else cfg.open_deg
            a0 = u(rd, lo_hi)
            angles = tuple(a0 if i == 0 else float(np.clip(a0 + rd.uniform(-5, 5), *lo_hi))
                           for i in range(n_leaves))
        dv = t / 2 + 0.01
        frame_parts = [
            box_arrays((-ow / 2 + fw / 2, 0, hd / 2), (fw, 2 * dv, hd)),
            box_arrays((ow / 2 - fw / 2, 0, hd / 2), (fw, 2 * dv, hd)),
            box_arrays((0, 0, hd + fw / 2), (ow, 2 * dv, fw)),
        ]
        leaf_w = clear / n_leaves - 0.008
        leaf_h = hd - 0.015
        hinge_v = t / 2 - 0.005
        leaves, handles, hinges = [], [], []
        for i, ang in enumerate(angles):
            sgn = 1.0 if i == 0 else -1.0
            th = math.radians(ang)
            hinge = np.array([sgn * (-clear / 2 + 0.004), hinge_v])
            d = np.array([sgn * math.cos(th), math.sin(th)])
            n = np.array([sgn * math.sin(th), -math.cos(th)])
            c = hinge + d * leaf_w / 2 + n * lt / 2
            heading = math.atan2(d[1], d[0])
            leaves.append(box_arrays((c[0], c[1], 0.01 + leaf_h / 2), (leaf_w, lt, leaf_h),
                                     heading))
            # a lever handle on both faces near the free edge, knuckles on the hinge line
            # (their centres on the swing-side wall face: they stand proud of it)
            handles += lever_handle_parts(hinge + d * leaf_w + n * lt / 2, d, n, lt)
            hinges += hinge_parts((hinge[0], t / 2), leaf_h)
        leaf_mat = material_for("door_leaf")
        leaf_app = sample_appearance(leaf_mat, "door_leaf", ra)
        space_of_door = side.space
        add(to_world(frame_parts), "door", "door_frame", f"door_{k}_frame", prior="door_frame",
            door_index=k, space_index=space_of_door)
        for i, leaf in enumerate(leaves):
            add(to_world([leaf]), "door", "door_leaf", f"door_{k}_leaf_{i}", material=leaf_mat,
                door_index=k, space_index=space_of_door, appearance=leaf_app)
        handle = add(to_world(handles), "door", "door_handle", f"door_{k}_handle",
                     prior="door_handle", door_index=k, space_index=space_of_door)
        # the hinges are the handle's metal (no draw of their own: the seed's other objects
        # keep their materials and looks)
        add(to_world(hinges), "door", "door_hinge", f"door_{k}_hinges", material=handle.material,
            door_index=k, space_index=space_of_door, appearance=handle.appearance)
        # doorway box (see frame.py): the frame's outline × its depth through the wall,
        # independent of the leaves' swing
        lo = np.array([-ow / 2, -dv, 0.0])
        hi = np.array([ow / 2, dv, hd + fw])
        cl = (lo + hi) / 2
        cw = rot @ cl + origin
        # boxes are symmetric under a half turn: report headings in [-pi/2, pi/2)
        heading = float(wrap_heading(yaw_u))
        box = (float(cw[0]), float(cw[1]), float(cw[2]), float(hi[0] - lo[0]),
               float(hi[1] - lo[1]), float(hi[2] - lo[2]), float(heading))
        doors.append(DoorSpec(
            index=k, kind="double" if plan["double"] else "single", state=state,
            swing_deg=tuple(float(a) for a in angles), width_m=float(clear), height_m=float(hd),
            center_world=(float(origin[0]), float(origin[1]), 0.0), wall_axis=side.axis,
            box_world=box, leads_to=int(plan["leads_to"]), leaf_material=leaf_mat))

    # ------------------------------------------------------------------ 5. windows
    sills: dict[int, list] = {}
    for k, plan in enumerate(window_plans):
        side = plan["side"]
        s0, s1, sill, top = plan["s0"], plan["s1"], plan["sill"], plan["top"]
        raster.opening[raster.sl(*_rect_of_band(side, s0, s1, 0.0, -t))] = True
        owner = side.space
        sills.setdefault(owner, []).append(
            box_arrays(_center_of_band(side, s0, s1, 0.0, -t, 0.0, sill),
                       _size_of_band(side, s0, s1, t, sill)))
        sills[owner].append(
            box_arrays(_center_of_band(side, s0, s1, 0.0, -t, top, height),
                       _size_of_band(side, s0, s1, t, height - top)))
        pane = box_arrays(_center_of_band(side, s0, s1, -t / 2 + 0.005, -t / 2 - 0.005, sill, top),
                          _size_of_band(side, s0, s1, 0.01, top - sill))
        add([pane], "window", "window", f"window_{k}", space_index=owner)

    # ------------------------------------------------------------------ 6. walls, floors, ceilings
    wall_mask = (raster.wall >= 0) & ~raster.opening
    for space in spaces:
        parts = []
        for i0, i1, j0, j1 in greedy_rects(wall_mask & (raster.wall == space.index)):
            x0, x1, y0, y1 = raster.cell_rect(i0, i1, j0, j1)
            parts.append(box_arrays(((x0 + x1) / 2, (y0 + y1) / 2, height / 2),
                                    (x1 - x0, y1 - y0, height)))
        parts += lintels.get(space.index, []) + sills.get(space.index, [])
        kind = "corridor_wall" if space.kind == "corridor" else "room_wall"
        if parts:
            add(parts, "wall", kind, f"wall_{space.index}", prior=kind,
                space_index=space.index)
    for space in spaces:
        x0, x1, y0, y1 = space.rect_m
        kind = "corridor_floor" if space.kind == "corridor" else "room_floor"
        floor = [box_arrays(((x0 + x1) / 2, (y0 + y1) / 2, -_FLOOR_THICKNESS_M / 2),
                            (x1 - x0, y1 - y0, _FLOOR_THICKNESS_M))]
        add(floor + thresholds.get(space.index, []), "floor", kind, f"floor_{space.index}",
            prior=kind, space_index=space.index)
        ceil = box_arrays(((x0 + x1) / 2, (y0 + y1) / 2, height + _FLOOR_THICKNESS_M / 2),
                          (x1 - x0, y1 - y0, _FLOOR_THICKNESS_M))
        add([ceil], "ceiling", "ceiling", f"ceiling_{space.index}", space_index=space.index)

    # ------------------------------------------------------------------ 7. props
    rp = _rng(seed, "props")

    def slot(side: _Side, w: float, categories: tuple[str, ...], tries: int = 12):
        for _ in range(tries):
            if side.length < w + 0.4:
                return None
            a = float(rp.uniform(side.u0 + 0.2, side.u1 - 0.2 - w))
            if side.free(a, a + w, categories):
                return a
        return None

    corridor_sides = [s for s in sides if s.role == "long"]
    n_ext = [0]

    def place_extinguisher(side: _Side) -> None:
        a = slot(side, 0.3, ("opening", "door", "window", "prop"))
        if a is None:
            return
        rad = float(rp.uniform(0.07, 0.09))
        h = float(rp.uniform(0.40, 0.55))
        z0 = float(rp.uniform(0.65, 0.9))
        s = a + 0.15
        base = side.point(s, 0.005 + rad, z0)
        body = cylinder_arrays(base, (0, 0, 1), rad, h, 16)
        head = box_arrays(side.point(s, 0.005 + rad, z0 + h + 0.05), (0.06, 0.06, 0.1))
        bracket = box_arrays(side.point(s, 0.0025 + 0.01, z0 + h * 0.6), (0.05, 0.05, 0.05))
        add([body, head, bracket], "fire_extinguisher", "fire_extinguisher",
            f"extinguisher_{n_ext[0]}", space_index=side.space)
        side.blocked.append((a, a + 0.3, "prop"))
        n_ext[0] += 1

    for space in [s for s in spaces if s.kind == "corridor"]:
        lo, hi = cfg.extinguishers_per_corridor
        for _ in range(int(rp.integers(lo, hi + 1))):
            cands = [s for s in corridor_sides if s.space == space.index]
            place_extinguisher(cands[int(rp.integers(len(cands)))])

    n_clutter = [0]
    for side in sides:
        if side.role not in ("long", "lat"):
            continue
        space_w = spaces[side.space].size_m[1 if spaces[side.space].axis == "x" else 0]
        room = side.role == "lat"
        lam = cfg.clutter_per_10m * side.length / 10.0 * (0.5 if room else 1.0)
        for _ in range(int(rp.poisson(lam))):
            kind = _choice(rp, cfg.clutter_kind_probs)
            max_depth = 0.6 if room else max(0.2, (space_w - 1.0) / 2)
            if kind == "cabinet":
                w, dep, h, z0 = rp.uniform(0.5, 1.0), min(rp.uniform(0.35, 0.55), max_depth), \
                    rp.uniform(0.8, 2.0), 0.0
            elif kind == "radiator":
                w, dep, h, z0 = rp.uniform(0.6, 1.5), rp.uniform(0.08, 0.12), \
                    rp.uniform(0.45, 0.7), rp.uniform(0.1, 0.15)
            else:
                rad = min(rp.uniform(0.15, 0.25), max_depth / 2)
                w, dep, h, z0 = 2 * rad, 2 * rad, rp.uniform(0.4, 0.8), 0.0
            cats = ("opening", "door", "prop") + (("window",) if kind == "cabinet" else ())
            a = slot(side, float(w), cats)
            if a is None:
                continue
            s = a + w / 2
            if kind == "bin":
                parts = [cylinder_arrays(side.point(s, 0.02 + w / 2, 0.0), (0, 0, 1), w / 2, h, 20)]
            elif kind == "radiator":
                fins = int(max(3, w / 0.1))
                parts = [box_arrays(side.point(s, 0.03 + dep / 2, z0 + h / 2),
                                    _along(side, w, dep, h))]
                for fi in range(fins):  # vertical fins give the radiator its look
                    fs = a + (fi + 0.5) * w / fins
                    parts.append(box_arrays(side.point(fs, 0.03 + dep + 0.01, z0 + h / 2),
                                            _along(side, 0.03, 0.02, h * 0.96)))
            else:
                parts = [box_arrays(side.point(s, 0.005 + dep / 2, z0 + h / 2),
                                    _along(side, w, dep, h))]
            add(parts, "clutter", kind, f"{kind}_{n_clutter[0]}", space_index=side.space)
            side.blocked.append((a, a + w, "prop"))
            n_clutter[0] += 1

    n_rail = 0
    for side in corridor_sides:
        if rp.uniform() >= cfg.handrail_probability:
            continue
        blocks = sorted((lo, hi) for lo, hi, cat in side.blocked
                        if cat in ("opening", "door") or (cat == "prop"))
        spans, cur = [], side.u0 + 0.1
        for lo, hi in blocks:
            if lo - 0.1 > cur:
                spans.append((cur, lo - 0.1))
            cur = max(cur, hi + 0.1)
        if side.u1 - 0.1 > cur:
            spans.append((cur, side.u1 - 0.1))
        parts = []
        zr = 0.9
        for a, b in spans:
            if b - a < 1.0:
                continue
            direction = (1, 0, 0) if side.axis == "x" else (0, 1, 0)
            parts.append(cylinder_arrays(side.point(a, 0.07, zr), direction, 0.022, b - a, 12))
            for s in np.linspace(a + 0.15, b - 0.15, max(2, int((b - a) / 1.5) + 1)):
                parts.append(box_arrays(side.point(float(s), 0.035, zr),
                                        _along(side, 0.02, 0.07, 0.02)))
        if parts:
            add(parts, "handrail", "handrail", f"handrail_{n_rail}", space_index=side.space)
            n_rail += 1

    # ------------------------------------------------------------------ 8. lights
    rl = _rng(seed, "lights")
    spacing = u(rl, cfg.light_spacing_m)
    square = rl.uniform() < 0.3
    n_light = 0
    light_app = sample_appearance("plastic", "light", rl, emission=cfg.light_radiance)
    for space in spaces:
        x0, x1, y0, y1 = space.rect_m
        if space.kind == "corridor":
            along = space.axis
            lo, hi = (x0, x1) if along == "x" else (y0, y1)
            n = max(1, int((hi - lo) / spacing))
            centers = [lo + (i + 0.5) * (hi - lo) / n for i in range(n)]
            size_a, size_c = (0.6, 0.6) if square else (1.2, 0.3)
        else:
            along = "x"
            centers = [(x0 + x1) / 2]
            size_a, size_c = 0.6, 0.6
        for cpos in centers:
            if along == "x":
                c, sz = (cpos, (y0 + y1) / 2, height - 0.015), (size_a, size_c, 0.03)
            else:
                c, sz = ((x0 + x1) / 2, cpos, height - 0.015), (size_c, size_a, 0.03)
            add([box_arrays(c, sz)], "ceiling", "light", f"light_{n_light}", prior="light",
                space_index=space.index, appearance=light_app)
            n_light += 1

    # ------------------------------------------------------------------ assemble
    meshes, objects = [], []
    for i, o in enumerate(objs):
        assert o.semantic in SEMANTIC_CLASSES and o.material in MATERIAL_CLASSES
        v, f = merge_arrays(o.parts)
        meshes.append(MaterialMesh(v, f, material=o.material, name=o.name, semantic=o.semantic))
        objects.append(WorldObject(i, o.name, o.semantic, o.material, o.kind, o.door_index,
                                   o.space_index, o.appearance))
    return World(
        seed=seed, config=cfg, layout=layout, ceiling_height_m=float(height),
        spaces=tuple(spaces), meshes=tuple(meshes), objects=tuple(objects), doors=tuple(doors),
        path_world=np.asarray(path, dtype=np.float64),
    )


def _along(side: _Side, w: float, d: float, h: float) -> tuple[float, float, float]:
    """Box size (x, y, z) [m] for ``w`` along the wall and ``d`` away from it."""
    return (w, d, h) if side.axis == "x" else (d, w, h)


def _center_of_band(side: _Side, a, b, d0, d1, z0, z1) -> tuple[float, float, float]:
    x0, x1, y0, y1 = _rect_of_band(side, a, b, d0, d1)
    return ((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2)


def _size_of_band(side: _Side, a, b, depth, h) -> tuple[float, float, float]:
    return _along(side, b - a, depth, h)


# re-exported names used by tests and statistics
DOOR_STATE_NAMES = DOOR_STATES
LAYOUT_NAMES = LAYOUTS
CLUTTER_NAMES = CLUTTER_KINDS
