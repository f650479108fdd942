"""The floor plan of a generated world: the build state its steps share, and steps 1–3.

:func:`sim2radar.worlds.generate.generate_world` runs eight steps over one :class:`Build`. The
first three decide where everything goes, without any geometry:

1. :func:`plan_layout` — the corridors (layout, sizes, wall thickness), the path along them and
   their wall faces (:class:`Side`).
2. :func:`plan_rooms_and_doors` — side rooms along the corridors' long walls, the door into each,
   blind doors on free wall stretches, end doors; the rooms' far and lateral wall faces.
3. :func:`plan_windows` — the wall raster (:class:`Raster`) and windows where it shows open
   outside behind a wall.

Every random decision draws from a named sub-stream (:attr:`Build.rng`), in a fixed order, so one
seed gives one world on every run; the steps 4–8 that turn the plan into meshes are in
:mod:`sim2radar.worlds.generate_parts`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sim2radar.worlds.appearance import sample_appearance
from sim2radar.worlds.config import WorldConfig
from sim2radar.worlds.frame import Appearance, DoorSpec, Space

__all__ = ["Build", "Side", "Raster", "DoorPlan", "WindowPlan", "PlacedObject", "STREAMS",
           "FLOOR_THICKNESS_M", "plan_layout", "plan_rooms_and_doors", "plan_windows",
           "uniform", "choice", "rect_of_band", "center_of_band", "size_of_band", "along"]

#: Random sub-stream of each kind of decision: ``np.random.default_rng([seed, STREAMS[name]])``.
STREAMS = {"layout": 1, "rooms": 2, "doors": 3, "materials": 4, "appearance": 5, "props": 6,
           "windows": 7, "lights": 8}
#: Thickness of floor and ceiling slabs and door thresholds [m].
FLOOR_THICKNESS_M = 0.05
_EPS = 1e-6


@dataclasses.dataclass
class Side:
    """A wall face of a space: runs along ``axis`` from ``u0`` to ``u1`` [m] at perpendicular
    coordinate ``coord`` [m]; ``inward`` (+1/-1) points from the face into the space.

    ``role`` is ``long`` (a corridor's long wall), ``end`` (a corridor's end wall), ``far`` (a
    room's wall opposite its door) or ``lat`` (a room's wall beside its door); ``blocked`` lists
    the taken stretches ``(a, b, category)`` [m], category ``opening``, ``door``, ``window`` or
    ``prop``.
    """

    space: int
    axis: str
    coord: float
    inward: int
    u0: float
    u1: float
    role: str
    blocked: list = dataclasses.field(default_factory=list)

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
        """Whether along-wall ``[a, b]`` [m] lies on the face and clear of the blocked
        stretches of ``categories``."""
        if a < self.u0 - _EPS or b > self.u1 + _EPS:
            return False
        return all(b <= lo + _EPS or a >= hi - _EPS
                   for lo, hi, cat in self.blocked if cat in categories)

    @property
    def length(self) -> float:
        return self.u1 - self.u0


@dataclasses.dataclass
class DoorPlan:
    """A door opening planned in ``side``: along-wall ``s0``..``s1`` [m] (frame outside to
    outside), ``double`` leaves, ``height_m`` [m] clear, into space ``leads_to`` (-1: blind or
    end door, nothing behind it)."""

    side: Side
    s0: float
    s1: float
    double: bool
    leads_to: int
    height_m: float


@dataclasses.dataclass
class WindowPlan:
    """A window planned in ``side``: along-wall ``s0``..``s1``, from ``sill`` to ``top`` [m]."""

    side: Side
    s0: float
    s1: float
    sill: float
    top: float


@dataclasses.dataclass
class PlacedObject:
    """One object before assembly: its (vertices, faces) parts and its table row."""

    parts: list
    semantic: str
    material: str
    kind: str
    name: str
    door_index: int = -1
    space_index: int = -1
    appearance: Appearance | None = None


class Raster:
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


@dataclasses.dataclass
class Build:
    """What the steps of :func:`~sim2radar.worlds.generate.generate_world` share: the seed, the
    config, the random streams, the plan (steps 1–3) and the objects made from it (steps 4–8).

    Attributes
    ----------
    seed : int
    cfg : WorldConfig
    rng : dict[str, numpy Generator] — one sub-stream per name of :data:`STREAMS`.
    layout : str — ``straight``, ``t_junction`` or ``l_turn`` (step 1).
    length_m, width_m, height_m : float [m] — main corridor length and width, ceiling height.
    t : float [m] — wall thickness.
    spaces : list[Space] — corridors, then rooms (steps 1, 2).
    sides : list[Side] — the wall faces (steps 1, 2).
    path : list[(x, y)] [m] — the centre-line polyline trajectories follow (step 1).
    junction : (x0, x1, side) or None — where the branch leaves the main corridor (step 1).
    door_plans, window_plans : list — openings to build (steps 2, 3).
    raster : Raster or None — the wall raster (step 3); doors and windows mark their openings.
    objs : list[PlacedObject] — the objects, in instance order (steps 4–8).
    doors : list[DoorSpec] — one per door plan (step 4).
    lintels, thresholds, sills : dict[int, list] — wall and floor parts above and below the
        openings, per owning space (steps 4, 5; built into walls and floors in step 6).
    """

    seed: int
    cfg: WorldConfig
    rng: dict[str, np.random.Generator] = dataclasses.field(init=False)
    layout: str = ""
    length_m: float = 0.0
    width_m: float = 0.0
    height_m: float = 0.0
    t: float = 0.0
    spaces: list[Space] = dataclasses.field(default_factory=list)
    sides: list[Side] = dataclasses.field(default_factory=list)
    path: list[tuple[float, float]] = dataclasses.field(default_factory=list)
    junction: tuple[float, float, int] | None = None
    door_plans: list[DoorPlan] = dataclasses.field(default_factory=list)
    window_plans: list[WindowPlan] = dataclasses.field(default_factory=list)
    raster: Raster | None = None
    objs: list[PlacedObject] = dataclasses.field(default_factory=list)
    doors: list[DoorSpec] = dataclasses.field(default_factory=list)
    lintels: dict[int, list] = dataclasses.field(default_factory=dict)
    thresholds: dict[int, list] = dataclasses.field(default_factory=dict)
    sills: dict[int, list] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        # each stream is its own generator: the order in which they are made does not matter
        self.rng = {name: np.random.default_rng([self.seed, k]) for name, k in STREAMS.items()}

    def q(self, x: float) -> float:
        """``x`` [m] snapped to the ``grid_m`` raster."""
        g = self.cfg.grid_m
        return round(x / g) * g

    def material_for(self, kind: str) -> str:
        """Draw a material for an object of ``kind`` from its prior (``materials`` stream)."""
        return choice(self.rng["materials"], self.cfg.material_priors[kind])

    def add(self, parts, semantic, kind, name, material=None, prior=None, door_index=-1,
            space_index=-1, appearance=None, emission=0.0) -> PlacedObject:
        """Append an object; its material is drawn from the prior of ``prior`` (default
        ``kind``) and its appearance from the ``appearance`` stream unless given."""
        mat = material or self.material_for(prior or kind)
        app = appearance or sample_appearance(mat, prior or kind, self.rng["appearance"],
                                              emission=emission)
        obj = PlacedObject(list(parts), semantic, mat, kind, name, door_index, space_index, app)
        self.objs.append(obj)
        return obj


def uniform(rng: np.random.Generator, lohi) -> float:
    """One draw from ``U(lo, hi)``."""
    return float(rng.uniform(*lohi))


def choice(rng: np.random.Generator, table: dict[str, float]) -> str:
    """One key of ``table`` drawn with the (normalised) probabilities its values give."""
    keys = list(table)
    p = np.array([table[k] for k in keys], dtype=np.float64)
    return keys[int(rng.choice(len(keys), p=p / p.sum()))]


def rect_of_band(side: Side, a: float, b: float, d0: float, d1: float):
    """World rect (x0, x1, y0, y1) [m] of along-wall [a, b] x inward distance [d0, d1]."""
    p0 = side.coord + side.inward * d0
    p1 = side.coord + side.inward * d1
    lo, hi = min(p0, p1), max(p0, p1)
    return (a, b, lo, hi) if side.axis == "x" else (lo, hi, a, b)


def along(side: Side, w: float, d: float, h: float) -> tuple[float, float, float]:
    """Box size (x, y, z) [m] for ``w`` along the wall and ``d`` away from it."""
    return (w, d, h) if side.axis == "x" else (d, w, h)


def center_of_band(side: Side, a, b, d0, d1, z0, z1) -> tuple[float, float, float]:
    """Centre [m] of the box along-wall [a, b] x inward [d0, d1] x height [z0, z1]."""
    x0, x1, y0, y1 = rect_of_band(side, a, b, d0, d1)
    return ((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2)


def size_of_band(side: Side, a, b, depth, h) -> tuple[float, float, float]:
    """Size [m] of a box along-wall [a, b], ``depth`` through the wall, ``h`` high."""
    return along(side, b - a, depth, h)


def _separation(r1, r2) -> float:
    gx = max(r1[0] - r2[1], r2[0] - r1[1])
    gy = max(r1[2] - r2[3], r2[2] - r1[3])
    return max(gx, gy)


def plan_layout(build: Build) -> None:
    """Step 1: the corridors. Adds the layout, the main corridor's length and width, the ceiling
    height, the wall thickness, the corridor spaces (a main corridor along +x and, for
    ``t_junction`` / ``l_turn``, a perpendicular branch along it / at its far end), the path
    and the corridors' wall faces (``long`` and ``end`` sides). Draws from ``layout``."""
    cfg, q, r = build.cfg, build.q, build.rng["layout"]
    layout = choice(r, cfg.layout_probs)
    length = q(uniform(r, cfg.corridor_length_m))
    width = q(uniform(r, cfg.corridor_width_m))
    height = q(uniform(r, cfg.ceiling_height_m))
    t = max(cfg.grid_m, q(uniform(r, cfg.wall_thickness_m)))
    spaces: list[Space] = [Space(0, "corridor", (0.0, length, 0.0, width), "x")]
    path = [(0.6, width / 2)]
    junction = None
    if layout != "straight":
        bw = q(uniform(r, cfg.corridor_width_m))
        bl = q(uniform(r, cfg.branch_length_m))
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

    sides: list[Side] = [
        Side(0, "x", 0.0, +1, 0.0, length, "long"),
        Side(0, "x", width, -1, 0.0, length, "long"),
        Side(0, "y", 0.0, +1, 0.0, width, "end"),
    ]
    if layout != "l_turn":
        sides.append(Side(0, "y", length, -1, 0.0, width, "end"))
    if junction is not None:
        xj0, xj1, side = junction
        main_side = sides[1] if side > 0 else sides[0]
        main_side.blocked.append((xj0, xj1, "opening"))
        bx0, bx1, by0, by1 = spaces[1].rect_m
        sides += [
            Side(1, "y", bx0, +1, by0, by1, "long"),
            Side(1, "y", bx1, -1, by0, by1, "long"),
        ]
        if side > 0:
            sides.append(Side(1, "x", by1, -1, bx0, bx1, "end"))
        else:
            sides.append(Side(1, "x", by0, +1, bx0, bx1, "end"))
    build.layout, build.length_m, build.width_m, build.height_m, build.t = (
        layout, length, width, height, t)
    build.spaces, build.path, build.junction, build.sides = spaces, path, junction, sides


def _plan_door(build: Build, side: Side, s_center: float | None, a: float, b: float,
               leads_to: int, allow_double: bool) -> bool:
    """Plan a door in along-wall ``[a, b]`` of ``side`` (centred on ``s_center`` if given, else
    at a drawn position); ``False`` if it does not fit or the stretch is taken. A double door
    that does not fit is tried again as a single one. Draws from ``doors``."""
    cfg, q, rd = build.cfg, build.q, build.rng["doors"]
    double = allow_double and rd.uniform() < cfg.door_double_probability
    clear = uniform(rd, cfg.door_double_width_m if double else cfg.door_single_width_m)
    ow = q(clear + 2 * cfg.door_frame_width_m)
    if b - a < ow + 0.2:
        if double:
            return _plan_door(build, side, s_center, a, b, leads_to, False)
        return False
    # max(): b - a can fall short of ow + 0.2 by a rounding error (q() rounds ow); the
    # draw then has an empty range (seed 1161 raised "high - low < 0")
    s0 = (q(rd.uniform(a + 0.1, max(b - 0.1 - ow, a + 0.1))) if s_center is None
          else q(s_center - ow / 2))
    s0 = min(max(s0, q(a + 0.1)), q(b - 0.1 - ow))
    if not side.free(s0 - 0.1, s0 + ow + 0.1, ("opening", "door")):
        return False
    side.blocked.append((s0 - 0.15, s0 + ow + 0.15, "door"))
    build.door_plans.append(DoorPlan(side=side, s0=s0, s1=s0 + ow, double=double,
                                     leads_to=leads_to,
                                     height_m=q(uniform(rd, cfg.door_height_m))))
    return True


def plan_rooms_and_doors(build: Build) -> None:
    """Step 2: rooms and doors. Walks each corridor ``long`` side adding side rooms (one wall
    thickness behind it, each with a single or double door), blind doors on free stretches and
    end doors on ``end`` sides; then each room's ``far`` wall face (for windows and props) and
    its two ``lat`` faces, with the door's swing zone kept clear of props. Draws from ``rooms``
    and ``doors``."""
    cfg, q, t, spaces = build.cfg, build.q, build.t, build.spaces
    rr, rd = build.rng["rooms"], build.rng["doors"]
    for side in [s for s in build.sides if s.role == "long"]:
        pos = side.u0 + q(rr.uniform(0.2, 1.5))
        while pos < side.u1 - 1.0:
            if rr.uniform() < cfg.room_probability:
                rw = q(uniform(rr, cfg.room_width_m))
                rdp = q(uniform(rr, cfg.room_depth_m))
                a, b = pos, min(pos + rw, side.u1 - 0.1)
                rect = rect_of_band(side, a, b, -t, -t - rdp)
                ok = (b - a >= cfg.room_width_m[0] - _EPS
                      and side.free(a, b, ("opening",))
                      and all(_separation(rect, s.rect_m) >= t - _EPS for s in spaces))
                if ok and _plan_door(build, side, None, a + 0.15, b - 0.15, len(spaces), True):
                    spaces.append(Space(len(spaces), "room", rect))
                    pos = b + t + q(uniform(rr, cfg.room_gap_m))
                    continue
            if rr.uniform() < cfg.blind_door_probability:
                _plan_door(build, side, None, pos, min(pos + 1.6, side.u1), -1, False)
            pos += q(rr.uniform(1.0, 3.0))
    for side in [s for s in build.sides if s.role == "end"]:
        if rd.uniform() < cfg.end_door_probability:
            _plan_door(build, side, (side.u0 + side.u1) / 2, side.u0, side.u1, -1, True)

    for room in spaces[1:]:
        if room.kind != "room":
            continue
        door_side = next(p.side for p in build.door_plans if p.leads_to == room.index)
        x0, x1, y0, y1 = room.rect_m
        if door_side.axis == "x":
            far = (Side(room.index, "x", y0, +1, x0, x1, "far") if door_side.inward > 0
                   else Side(room.index, "x", y1, -1, x0, x1, "far"))
            lat = [Side(room.index, "y", x0, +1, y0, y1, "lat"),
                   Side(room.index, "y", x1, -1, y0, y1, "lat")]
        else:
            far = (Side(room.index, "y", x0, +1, y0, y1, "far") if door_side.inward > 0
                   else Side(room.index, "y", x1, -1, y0, y1, "far"))
            lat = [Side(room.index, "x", y0, +1, x0, x1, "lat"),
                   Side(room.index, "x", y1, -1, x0, x1, "lat")]
        # keep room props away from the door's swing zone (1.2 m from the door wall)
        for ls in lat:
            near = door_side.coord  # the door wall's face coordinate on the corridor side
            if abs(ls.u0 - near) < abs(ls.u1 - near):
                ls.blocked.append((ls.u0, ls.u0 + 1.3 + t, "door"))
            else:
                ls.blocked.append((ls.u1 - 1.3 - t, ls.u1, "door"))
        build.sides += [far, *lat]


def plan_windows(build: Build) -> None:
    """Step 3: the wall raster and the windows. Adds the :class:`Raster` of the spaces and a
    window plan wherever a corridor ``long`` or room ``far`` side has a free stretch with open
    outside (no space or wall within 6 m) behind it. Draws from ``windows``."""
    cfg, q, t, g = build.cfg, build.q, build.t, build.cfg.grid_m
    raster = build.raster = Raster(build.spaces, t, g)
    rw_ = build.rng["windows"]
    for side in build.sides:
        if side.role not in ("long", "far"):
            continue
        pos = side.u0 + 0.4
        while pos < side.u1 - 1.0:
            ww = q(uniform(rw_, cfg.window_width_m))
            place = rw_.uniform() < cfg.window_probability
            a, b = pos, pos + ww
            if place and b <= side.u1 - 0.3 and side.free(a - 0.2, b + 0.2, ("opening", "door")):
                behind = rect_of_band(side, a - 0.3, b + 0.3, -t - g, -t - 6.0)
                if raster.void(*behind):
                    sill = q(uniform(rw_, cfg.window_sill_m))
                    top = q(uniform(rw_, cfg.window_top_m))
                    build.window_plans.append(WindowPlan(side=side, s0=a, s1=b,
                                                         sill=min(sill, top - 0.3), top=top))
                    side.blocked.append((a - 0.1, b + 0.1, "window"))
                    pos = b + q(rw_.uniform(1.0, 3.0))
                    continue
            pos += q(rw_.uniform(1.5, 3.0))
