"""The objects of a generated world: steps 4–8, the plan of :mod:`~sim2radar.worlds.
generate_plan` turned into meshes.

4. :func:`build_doors` — frames, leaves, handles and hinges in each planned opening, the wall
   above it (lintel) and the threshold below; the doors' :class:`~sim2radar.worlds.frame.DoorSpec`.
5. :func:`build_windows` — the wall below and above each window and its pane.
6. :func:`build_walls_floors_ceilings` — the walls (raster cells minus openings, merged into
   boxes), floor and ceiling slabs.
7. :func:`place_props` — fire extinguishers, clutter (cabinets, radiators, bins), handrails.
8. :func:`place_lights` — ceiling light panels.

Each object draws its material (``materials`` stream) and appearance (``appearance`` stream)
as :meth:`~sim2radar.worlds.generate_plan.Build.add` appends it, so objects keep their looks only
if they are added in the same order: the steps run in the order above.
"""

from __future__ import annotations

import math

import numpy as np

from sim2radar.boxes import wrap_heading
from sim2radar.door_parts import hinge_parts, lever_handle_parts
from sim2radar.worlds.appearance import sample_appearance
from sim2radar.worlds.frame import DoorSpec
from sim2radar.worlds.generate_plan import (
    FLOOR_THICKNESS_M,
    Build,
    DoorPlan,
    Side,
    along,
    center_of_band,
    choice,
    rect_of_band,
    size_of_band,
    uniform,
)
from sim2radar.worlds.geometry import box_arrays, cylinder_arrays, greedy_rects, yaw_matrix

__all__ = ["build_doors", "build_windows", "build_walls_floors_ceilings", "place_props",
           "place_lights"]


def build_doors(build: Build) -> None:
    """Step 4: the doors. For each door plan, in order: marks the opening in the raster, adds
    the lintel above it and the threshold below it (a slab behind blind and end doors), draws
    the door's state and leaf angles (``doors`` stream), and adds its frame, leaves, handles and
    hinges as objects and its :class:`DoorSpec`."""
    for k, plan in enumerate(build.door_plans):
        _build_door(build, k, plan)


def _build_door(build: Build, k: int, plan: DoorPlan) -> None:
    cfg, t, height, raster = build.cfg, build.t, build.height_m, build.raster
    rd = build.rng["doors"]
    fw = cfg.door_frame_width_m
    lt = cfg.door_leaf_thickness_m
    side = plan.side
    s0, s1, hd = plan.s0, plan.s1, plan.height_m
    ow = s1 - s0
    clear = ow - 2 * fw
    raster.opening[raster.sl(*rect_of_band(side, s0, s1, 0.0, -t))] = True
    owner = side.space
    build.lintels.setdefault(owner, []).append(
        box_arrays(center_of_band(side, s0, s1, 0.0, -t, hd + fw, height),
                   size_of_band(side, s0, s1, t, height - hd - fw)))
    build.thresholds.setdefault(owner, []).append(
        box_arrays(center_of_band(side, s0, s1, 0.0, -t, -FLOOR_THICKNESS_M, 0.0),
                   size_of_band(side, s0, s1, t, FLOOR_THICKNESS_M)))
    if plan.leads_to < 0:
        # nothing is modelled behind a blind/end door: back it with a slab so no ray
        # escapes through the gaps around the leaf
        build.lintels[owner].append(
            box_arrays(center_of_band(side, s0 - 0.05, s1 + 0.05, -t, -t - 0.05, 0.0, height),
                       size_of_band(side, s0 - 0.05, s1 + 0.05, 0.05, height)))
    # local door frame: u along the wall, v through the wall towards the swing side, z up
    yaw_v = side.behind_yaw()
    yaw_u = yaw_v - math.pi / 2
    rot = yaw_matrix(yaw_u)
    origin = side.point((s0 + s1) / 2, -t / 2, 0.0)

    def to_world(parts):
        return [(v @ rot.T + origin, f) for v, f in parts]

    state = choice(rd, cfg.door_state_probs) if plan.leads_to >= 0 else "closed"
    n_leaves = 2 if plan.double else 1
    if state == "closed":
        angles = (0.0,) * n_leaves
    else:
        lo_hi = cfg.ajar_deg if state == "ajar" else cfg.open_deg
        a0 = uniform(rd, lo_hi)
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
        leaves.append(box_arrays((c[0], c[1], 0.01 + leaf_h / 2), (leaf_w, lt, leaf_h), heading))
        # a lever handle on both faces near the free edge, knuckles on the hinge line
        # (their centres on the swing-side wall face: they stand proud of it)
        handles += lever_handle_parts(hinge + d * leaf_w + n * lt / 2, d, n, lt)
        hinges += hinge_parts((hinge[0], t / 2), leaf_h)
    leaf_mat = build.material_for("door_leaf")
    leaf_app = sample_appearance(leaf_mat, "door_leaf", build.rng["appearance"])
    build.add(to_world(frame_parts), "door", "door_frame", f"door_{k}_frame",
              prior="door_frame", door_index=k, space_index=side.space)
    for i, leaf in enumerate(leaves):
        build.add(to_world([leaf]), "door", "door_leaf", f"door_{k}_leaf_{i}", material=leaf_mat,
                  door_index=k, space_index=side.space, appearance=leaf_app)
    handle = build.add(to_world(handles), "door", "door_handle", f"door_{k}_handle",
                       prior="door_handle", door_index=k, space_index=side.space)
    # the hinges are the handle's metal (no draw of their own: the seed's other objects
    # keep their materials and looks)
    build.add(to_world(hinges), "door", "door_hinge", f"door_{k}_hinges",
              material=handle.material, door_index=k, space_index=side.space,
              appearance=handle.appearance)
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
    build.doors.append(DoorSpec(
        index=k, kind="double" if plan.double else "single", state=state,
        swing_deg=tuple(float(a) for a in angles), width_m=float(clear), height_m=float(hd),
        center_world=(float(origin[0]), float(origin[1]), 0.0), wall_axis=side.axis,
        box_world=box, leads_to=int(plan.leads_to), leaf_material=leaf_mat))


def build_windows(build: Build) -> None:
    """Step 5: the windows. For each window plan, marks the opening in the raster, adds the
    wall below the sill and above the top (``sills``, built into the walls in step 6) and a
    1 cm pane in the wall's mid-plane as an object."""
    t, height, raster = build.t, build.height_m, build.raster
    for k, plan in enumerate(build.window_plans):
        side = plan.side
        s0, s1, sill, top = plan.s0, plan.s1, plan.sill, plan.top
        raster.opening[raster.sl(*rect_of_band(side, s0, s1, 0.0, -t))] = True
        owner = side.space
        build.sills.setdefault(owner, []).append(
            box_arrays(center_of_band(side, s0, s1, 0.0, -t, 0.0, sill),
                       size_of_band(side, s0, s1, t, sill)))
        build.sills[owner].append(
            box_arrays(center_of_band(side, s0, s1, 0.0, -t, top, height),
                       size_of_band(side, s0, s1, t, height - top)))
        pane = box_arrays(center_of_band(side, s0, s1, -t / 2 + 0.005, -t / 2 - 0.005, sill, top),
                          size_of_band(side, s0, s1, 0.01, top - sill))
        build.add([pane], "window", "window", f"window_{k}", space_index=owner)


def build_walls_floors_ceilings(build: Build) -> None:
    """Step 6: one wall object per space (its raster wall cells minus the door and window
    openings, merged into boxes, with its lintels and sills), then per space a floor slab (with
    the door thresholds) and a ceiling slab, each :data:`FLOOR_THICKNESS_M` thick."""
    height, raster = build.height_m, build.raster
    wall_mask = (raster.wall >= 0) & ~raster.opening
    for space in build.spaces:
        parts = []
        for i0, i1, j0, j1 in greedy_rects(wall_mask & (raster.wall == space.index)):
            x0, x1, y0, y1 = raster.cell_rect(i0, i1, j0, j1)
            parts.append(box_arrays(((x0 + x1) / 2, (y0 + y1) / 2, height / 2),
                                    (x1 - x0, y1 - y0, height)))
        parts += build.lintels.get(space.index, []) + build.sills.get(space.index, [])
        kind = "corridor_wall" if space.kind == "corridor" else "room_wall"
        if parts:
            build.add(parts, "wall", kind, f"wall_{space.index}", prior=kind,
                      space_index=space.index)
    for space in build.spaces:
        x0, x1, y0, y1 = space.rect_m
        kind = "corridor_floor" if space.kind == "corridor" else "room_floor"
        floor = [box_arrays(((x0 + x1) / 2, (y0 + y1) / 2, -FLOOR_THICKNESS_M / 2),
                            (x1 - x0, y1 - y0, FLOOR_THICKNESS_M))]
        build.add(floor + build.thresholds.get(space.index, []), "floor", kind,
                  f"floor_{space.index}", prior=kind, space_index=space.index)
        ceil = box_arrays(((x0 + x1) / 2, (y0 + y1) / 2, height + FLOOR_THICKNESS_M / 2),
                          (x1 - x0, y1 - y0, FLOOR_THICKNESS_M))
        build.add([ceil], "ceiling", "ceiling", f"ceiling_{space.index}",
                  space_index=space.index)


def _slot(build: Build, side: Side, w: float, categories: tuple[str, ...],
          tries: int = 12) -> float | None:
    """A drawn along-wall start [m] of a free ``w``-wide stretch of ``side`` (``props``
    stream), or ``None`` after ``tries`` taken draws."""
    rp = build.rng["props"]
    for _ in range(tries):
        if side.length < w + 0.4:
            return None
        a = float(rp.uniform(side.u0 + 0.2, side.u1 - 0.2 - w))
        if side.free(a, a + w, categories):
            return a
    return None


def place_props(build: Build) -> None:
    """Step 7: the props, drawn from ``props``: fire extinguishers on the corridors' long walls
    (``extinguishers_per_corridor`` each), Poisson clutter (cabinets, radiators, bins) along
    corridor and room walls, and handrails along the free stretches of corridor walls."""
    corridor_sides = [s for s in build.sides if s.role == "long"]
    _place_extinguishers(build, corridor_sides)
    _place_clutter(build)
    _place_handrails(build, corridor_sides)


def _place_extinguishers(build: Build, corridor_sides: list[Side]) -> None:
    rp = build.rng["props"]
    n_ext = 0
    for space in [s for s in build.spaces if s.kind == "corridor"]:
        lo, hi = build.cfg.extinguishers_per_corridor
        for _ in range(int(rp.integers(lo, hi + 1))):
            cands = [s for s in corridor_sides if s.space == space.index]
            side = cands[int(rp.integers(len(cands)))]
            a = _slot(build, side, 0.3, ("opening", "door", "window", "prop"))
            if a is None:
                continue
            rad = float(rp.uniform(0.07, 0.09))
            h = float(rp.uniform(0.40, 0.55))
            z0 = float(rp.uniform(0.65, 0.9))
            s = a + 0.15
            base = side.point(s, 0.005 + rad, z0)
            body = cylinder_arrays(base, (0, 0, 1), rad, h, 16)
            head = box_arrays(side.point(s, 0.005 + rad, z0 + h + 0.05), (0.06, 0.06, 0.1))
            bracket = box_arrays(side.point(s, 0.0025 + 0.01, z0 + h * 0.6), (0.05, 0.05, 0.05))
            build.add([body, head, bracket], "fire_extinguisher", "fire_extinguisher",
                      f"extinguisher_{n_ext}", space_index=side.space)
            side.blocked.append((a, a + 0.3, "prop"))
            n_ext += 1


def _place_clutter(build: Build) -> None:
    cfg, spaces, rp = build.cfg, build.spaces, build.rng["props"]
    n_clutter = 0
    for side in build.sides:
        if side.role not in ("long", "lat"):
            continue
        space_w = spaces[side.space].size_m[1 if spaces[side.space].axis == "x" else 0]
        room = side.role == "lat"
        lam = cfg.clutter_per_10m * side.length / 10.0 * (0.5 if room else 1.0)
        for _ in range(int(rp.poisson(lam))):
            kind = choice(rp, cfg.clutter_kind_probs)
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
            a = _slot(build, side, float(w), cats)
            if a is None:
                continue
            s = a + w / 2
            if kind == "bin":
                parts = [cylinder_arrays(side.point(s, 0.02 + w / 2, 0.0), (0, 0, 1), w / 2, h, 20)]
            elif kind == "radiator":
                fins = int(max(3, w / 0.1))
                parts = [box_arrays(side.point(s, 0.03 + dep / 2, z0 + h / 2),
                                    along(side, w, dep, h))]
                for fi in range(fins):  # vertical fins give the radiator its look
                    fs = a + (fi + 0.5) * w / fins
                    parts.append(box_arrays(side.point(fs, 0.03 + dep + 0.01, z0 + h / 2),
                                            along(side, 0.03, 0.02, h * 0.96)))
            else:
                parts = [box_arrays(side.point(s, 0.005 + dep / 2, z0 + h / 2),
                                    along(side, w, dep, h))]
            build.add(parts, "clutter", kind, f"{kind}_{n_clutter}", space_index=side.space)
            side.blocked.append((a, a + w, "prop"))
            n_clutter += 1


def _place_handrails(build: Build, corridor_sides: list[Side]) -> None:
    rp = build.rng["props"]
    n_rail = 0
    for side in corridor_sides:
        if rp.uniform() >= build.cfg.handrail_probability:
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
                                        along(side, 0.02, 0.07, 0.02)))
        if parts:
            build.add(parts, "handrail", "handrail", f"handrail_{n_rail}",
                      space_index=side.space)
            n_rail += 1


def place_lights(build: Build) -> None:
    """Step 8: ceiling light panels, drawn from ``lights``: along each corridor at a drawn
    spacing (1.2 m × 0.3 m strips, or 0.6 m squares in 30 % of worlds), one 0.6 m square per
    room, all sharing one emissive appearance of ``light_radiance``."""
    cfg, height, rl = build.cfg, build.height_m, build.rng["lights"]
    spacing = uniform(rl, cfg.light_spacing_m)
    square = rl.uniform() < 0.3
    n_light = 0
    light_app = sample_appearance("plastic", "light", rl, emission=cfg.light_radiance)
    for space in build.spaces:
        x0, x1, y0, y1 = space.rect_m
        if space.kind == "corridor":
            axis = space.axis
            lo, hi = (x0, x1) if axis == "x" else (y0, y1)
            n = max(1, int((hi - lo) / spacing))
            centers = [lo + (i + 0.5) * (hi - lo) / n for i in range(n)]
            size_a, size_c = (0.6, 0.6) if square else (1.2, 0.3)
        else:
            axis = "x"
            centers = [(x0 + x1) / 2]
            size_a, size_c = 0.6, 0.6
        for cpos in centers:
            if axis == "x":
                c, sz = (cpos, (y0 + y1) / 2, height - 0.015), (size_a, size_c, 0.03)
            else:
                c, sz = ((x0 + x1) / 2, cpos, height - 0.015), (size_c, size_a, 0.03)
            build.add([box_arrays(c, sz)], "ceiling", "light", f"light_{n_light}", prior="light",
                      space_index=space.index, appearance=light_app)
            n_light += 1
