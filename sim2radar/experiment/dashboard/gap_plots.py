"""The sim–real gap report's figures as Plotly figures, drawn from the numbers of ``gap.json``
(:func:`sim2radar.evaluate.gap.write_gap_report`): the page shows them at its own size, with
hover, zoom and legends, where the report's PNGs (:mod:`sim2radar.evaluate.gap_figures`, which
these follow panel by panel) were squeezed into a column.

    GAP_PLOTS[name] -> GapPlot(title, has_numbers(gap), figure(gap))

one per figure name of ``gap.json["figures"]``: ``overlay`` (one frame, sim over real: the
paper's Figure 3), ``points`` (points per frame), ``azimuth``, ``range``, ``intensity``,
``artefacts`` (sidelobe share against its control, Doppler, range and below-floor shares) and
``fidelity`` (where the points are against the true geometry, the door label boxes).
``has_numbers`` says whether a report holds what the figure needs (a report written before
``overlay`` and ``points`` were added to ``gap.json`` lacks them: the page then shows that
PNG); ``figure`` returns ``{"data": [...], "layout": {...}}``.

Every trace carries ``meta = {"role": "gap", "figure": name, "side": "sim" | "real" | None}``.
Pure functions of the ``gap.json`` document; a share is drawn in %, an unknown one (null in
``gap.json``: a dataset that cannot measure it) is written "unknown", never drawn as 0.
"""

from __future__ import annotations

import dataclasses
import json
import math
import statistics
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from sim2radar.evaluate.fidelity import BEHIND_SURFACE_M, FAR_RANGE_FRACTION
from sim2radar.experiment.dashboard.labels import num

__all__ = ["GAP_PLOTS", "GapPlot", "SIDE_COLOURS"]

#: colours of the two datasets, as the report's PNGs draw them (the paper's Figure 3: simulated
#: radar in red, real radar in blue; matplotlib's tab:red and tab:blue)
SIDE_COLOURS = {"sim": "#d62728", "real": "#1f77b4"}
#: Plotly's layout template of every figure (as :mod:`.figures`)
_TEMPLATE = "plotly_white"
#: door label boxes with fewer points than this count as weak (the report's ``labels_under_5``)
_FEW_POINTS = 5


@dataclasses.dataclass(frozen=True)
class GapPlot:
    """One figure of the gap report.

    Attributes
    ----------
    title : what the figure shows, one line (the page's caption).
    has_numbers : ``gap.json`` document -> whether it holds the figure's numbers.
    figure : ``gap.json`` document -> the Plotly figure (call only where ``has_numbers``).
    """

    title: str
    has_numbers: Callable[[Mapping[str, Any]], bool]
    figure: Callable[[Mapping[str, Any]], dict[str, Any]]


def _fig_json(fig) -> dict[str, Any]:
    return json.loads(fig.to_json())


def _meta(figure: str, side: str | None, **more: Any) -> dict[str, Any]:
    return {"role": "gap", "figure": figure, "side": side, **more}


def _section(gap: Mapping[str, Any], key: str) -> Mapping[str, Any]:
    value = gap.get(key)
    return value if isinstance(value, Mapping) else {}


def _numbers(v: Any) -> bool:
    """A non-empty list of numbers (null allowed: a NaN written as null)."""
    return isinstance(v, list) and bool(v) and all(
        x is None or (isinstance(x, int | float) and not isinstance(x, bool)) for x in v)


def _histogram(edges: Any, *fractions: Any) -> bool:
    """Bin edges and one fraction per bin for each of ``fractions``."""
    return _numbers(edges) and all(_numbers(f) and len(f) == len(edges) - 1 for f in fractions)


def _stairs(edges: Sequence[float], fractions: Sequence[Any]) -> tuple[list, list, list]:
    """A histogram as a step line: x at each bin's left edge and the last right edge, y in %
    (``line_shape="hv"``), and each point's bin ``[lo, hi)`` for the hover."""
    y = [None if num(f) is None else 100 * num(f) for f in fractions]
    x = list(edges)
    bins = [[edges[i], edges[i + 1]] for i in range(len(fractions))]
    return x, [*y, y[-1] if y else None], [*bins, bins[-1] if bins else None]


def _stairs_trace(edges, fractions, *, name: str, side: str, figure: str, unit: str,
                  dash: str | None = None, fill: bool = False, xaxis: str = "x",
                  yaxis: str = "y") -> Any:
    import plotly.graph_objects as go

    x, y, bins = _stairs(edges, fractions)
    colour = SIDE_COLOURS[side]
    return go.Scatter(
        x=x, y=y, mode="lines", line={"shape": "hv", "color": colour, "width": 2,
                                      "dash": dash or "solid"},
        fill="tozeroy" if fill else None, fillcolor=_rgba(colour, 0.25) if fill else None,
        name=name, customdata=bins, xaxis=xaxis, yaxis=yaxis,
        meta=_meta(figure, side),
        hovertemplate=(f"{name}<br>%{{customdata[0]:.4g}} to %{{customdata[1]:.4g}} {unit}: "
                       "%{y:.2f} % of points<extra></extra>"))


def _rgba(hex_colour: str, alpha: float) -> str:
    h = hex_colour.lstrip("#")
    r, g, b = (int(h[i:i + 2], 16) for i in (0, 2, 4))
    return f"rgba({r}, {g}, {b}, {alpha})"


def _layout(fig, title: str, height: int = 440, **more: Any) -> None:
    fig.update_layout(template=_TEMPLATE, height=height, title={"text": title},
                      margin={"l": 60, "r": 20, "t": 60, "b": 55},
                      legend={"orientation": "h", "y": -0.2}, **more)


def _pct_text(v: Any, digits: int = 1) -> str:
    f = num(v)
    return "unknown" if f is None else f"{100 * f:.{digits}f} %"


def _domain(gap: Mapping[str, Any], side: str) -> str:
    d = str(_section(gap, side).get("domain") or "")
    return d if len(d) <= 28 else d[:27] + "…"


# ------------------------------------------------------------------------- histograms
def _has_azimuth(gap: Mapping[str, Any]) -> bool:
    a = _section(gap, "azimuth")
    return _histogram(a.get("edges_deg"), a.get("sim_fraction"), a.get("real_fraction"))


def azimuth_figure(gap: Mapping[str, Any]) -> dict[str, Any]:
    """Azimuth coverage: each dataset's share of points per azimuth bin [%], positive azimuth
    (left) to the left as in a bird's-eye view; the legend gives each effective FOV."""
    import plotly.graph_objects as go

    a = _section(gap, "azimuth")
    fov = a.get("effective_fov_deg") if isinstance(a.get("effective_fov_deg"), Mapping) else {}
    edges = a["edges_deg"]
    fig = go.Figure()
    for side in ("real", "sim"):
        width = num(fov.get(side))
        label = f"{side}: effective FOV {'n/a' if width is None else f'{width:.1f}°'}"
        fig.add_trace(_stairs_trace(edges, a[f"{side}_fraction"], name=label, side=side,
                                    figure="azimuth", unit="°"))
    used = [i for i, (s, r) in enumerate(zip(a["sim_fraction"], a["real_fraction"],
                                              strict=True)) if (num(s) or 0) + (num(r) or 0) > 0]
    lim = 75.0
    if used:
        lim = max(lim, abs(edges[used[0]]) + 5.0, abs(edges[used[-1] + 1]) + 5.0)
    lim = min(lim, 180.0)
    _layout(fig, "azimuth coverage (the effective FOV: see the table above)",
            xaxis={"title": {"text": "azimuth atan2(y, x) [°] (positive = left)"},
                   "range": [lim, -lim]},
            yaxis={"title": {"text": f"points per {edges[1] - edges[0]:g}° bin [%]"},
                   "rangemode": "tozero"})
    return _fig_json(fig)


def _has_range(gap: Mapping[str, Any]) -> bool:
    r = _section(gap, "range")
    return _histogram(r.get("edges_m"), r.get("sim_fraction"), r.get("real_fraction"))


def range_figure(gap: Mapping[str, Any]) -> dict[str, Any]:
    """Range coverage: each dataset's share of points per range bin [%]."""
    import plotly.graph_objects as go

    r = _section(gap, "range")
    edges = r["edges_m"]
    fig = go.Figure()
    for side in ("real", "sim"):
        fig.add_trace(_stairs_trace(edges, r[f"{side}_fraction"], name=side, side=side,
                                    figure="range", unit="m"))
    _layout(fig, "range coverage",
            xaxis={"title": {"text": "range |(x, y, z)| [m]"}, "rangemode": "tozero"},
            yaxis={"title": {"text": f"points per {edges[1] - edges[0]:g} m bin [%]"},
                   "rangemode": "tozero"})
    return _fig_json(fig)


def _has_intensity(gap: Mapping[str, Any]) -> bool:
    i = _section(gap, "intensity")
    return _histogram(i.get("edges_db"), i.get("real"), i.get("sim_before"),
                      i.get("sim_after"))


def intensity_figure(gap: Mapping[str, Any]) -> dict[str, Any]:
    """Intensity distributions [%]: real (filled), sim as simulated (dashed) and after the
    log-space histogram matching (solid)."""
    import plotly.graph_objects as go

    i = _section(gap, "intensity")
    edges = i["edges_db"]
    fig = go.Figure()
    fig.add_trace(_stairs_trace(edges, i["real"], name="real", side="real",
                                figure="intensity", unit="dB", fill=True))
    fig.add_trace(_stairs_trace(edges, i["sim_before"], name="sim (as simulated)", side="sim",
                                figure="intensity", unit="dB", dash="dash"))
    fig.add_trace(_stairs_trace(edges, i["sim_after"], name="sim (histogram-matched)",
                                side="sim", figure="intensity", unit="dB"))
    _layout(fig, "intensity distributions (log-space histogram matching; fitted on: see the "
                 "table above)",
            xaxis={"title": {"text": "intensity [dB]"}},
            yaxis={"title": {"text": f"points per {edges[1] - edges[0]:.3g} dB bin [%]"},
                   "rangemode": "tozero"})
    return _fig_json(fig)


def _has_points(gap: Mapping[str, Any]) -> bool:
    p = _section(gap, "points")
    return all(isinstance(p.get(k), list) and all(num(c) is not None for c in p[k])
               for k in ("sim_counts", "real_counts")) and bool(
        p.get("sim_counts") or p.get("real_counts"))


def points_figure(gap: Mapping[str, Any]) -> dict[str, Any]:
    """Points per frame: a histogram of each dataset's frames (40 shared bins), a dashed line
    at each mean; the title gives the sim/real density."""
    import plotly.graph_objects as go

    p = _section(gap, "points")
    top = max([*(num(c) for c in p["sim_counts"]), *(num(c) for c in p["real_counts"]), 1.0])
    size = (top * 1.02 + 1) / 40
    fig = go.Figure()
    for side in ("real", "sim"):
        counts = [num(c) for c in p[f"{side}_counts"]]
        if not counts:
            continue
        mean, median = statistics.fmean(counts), statistics.median(counts)
        fig.add_trace(go.Histogram(
            x=counts, xbins={"start": 0, "end": top * 1.02 + 1, "size": size},
            marker={"color": SIDE_COLOURS[side]}, opacity=0.55,
            name=f"{side}: mean {mean:,.0f}, median {median:,.0f} ({len(counts)} frames)",
            meta=_meta("points", side),
            hovertemplate=f"{side}: %{{y}} frame(s) with %{{x}} points<extra></extra>"))
        fig.add_vline(x=mean, line={"color": SIDE_COLOURS[side], "dash": "dash", "width": 1})
    ratio = num(gap.get("points_ratio"))
    _layout(fig, "points per frame — sim/real density "
            + ("n/a" if ratio is None else f"{100 * ratio:.0f} %"), barmode="overlay",
            xaxis={"title": {"text": "points per frame"}, "rangemode": "tozero"},
            yaxis={"title": {"text": "frames"}})
    return _fig_json(fig)


# ------------------------------------------------------------------------------ overlay
def _points4(v: Any) -> bool:
    return isinstance(v, list) and all(
        isinstance(p, list) and len(p) >= 3 and all(num(x) is not None for x in p[:3])
        for p in v)


def _has_overlay(gap: Mapping[str, Any]) -> bool:
    o = _section(gap, "overlay")
    return (_points4(o.get("sim_points")) and _points4(o.get("real_points"))
            and isinstance(o.get("boxes", []), list))


def _box_outline(box: Sequence[float]) -> tuple[list[float], list[float]]:
    """The bird's-eye outline of a label box ``x y z dx dy dz heading`` [m, rad]: its four
    bottom corners and the first again (x forward, y left; heading about +z)."""
    x, y, _, dx, dy, _, h = (float(v) for v in box[:7])
    c, s = math.cos(h), math.sin(h)
    corners = [(dx / 2, dy / 2), (-dx / 2, dy / 2), (-dx / 2, -dy / 2), (dx / 2, -dy / 2)]
    pts = [(x + c * u - s * v, y + s * u + c * v) for u, v in corners]
    pts.append(pts[0])
    return [p[0] for p in pts], [p[1] for p in pts]


def overlay_figure(gap: Mapping[str, Any]) -> dict[str, Any]:
    """One frame's sim (red) and real (blue) points on top of each other (the paper's
    Figure 3): left a bird's-eye view (x forward up, y left to the left, equal scales, the
    label boxes dashed), right the side view (height z against the same x)."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    o = _section(gap, "overlay")
    fig = make_subplots(rows=1, cols=2, shared_yaxes=True, column_widths=[0.72, 0.28],
                        horizontal_spacing=0.04,
                        subplot_titles=("bird's-eye view", "side view"))
    frames = {"sim": o.get("sim_frame"), "real": o.get("real_frame")}
    for side, size, opacity in (("real", 3, 0.6), ("sim", 5, 0.9)):
        pts = o[f"{side}_points"]
        xs, ys, zs = ([float(p[k]) for p in pts] for k in range(3))
        cd = [[num(p[3]) if len(p) > 3 else None, y, z] for p, y, z in zip(pts, ys, zs,
                                                                            strict=True)]
        name = f"{side} ({len(pts):,} points, frame {frames[side]})"
        hover = (f"{side}<br>x %{{y:.2f}} m, y %{{customdata[1]:.2f}} m, z "
                 "%{customdata[2]:.2f} m<br>%{customdata[0]:.1f} dB<extra></extra>")
        common = {"mode": "markers", "legendgroup": side,
                  "marker": {"color": SIDE_COLOURS[side], "size": size, "opacity": opacity}}
        fig.add_trace(go.Scatter(
            x=ys, y=xs, name=name, customdata=cd,
            meta=_meta("overlay", side, view="bev"), hovertemplate=hover, **common),
            row=1, col=1)
        fig.add_trace(go.Scatter(
            x=zs, y=xs, name=name, showlegend=False, customdata=cd,
            meta=_meta("overlay", side, view="side"), hovertemplate=hover, **common),
            row=1, col=2)
    for k, box in enumerate(o.get("boxes") or []):
        if not (isinstance(box, list) and len(box) >= 7 and all(num(v) is not None
                                                                for v in box[:7])):
            continue
        bx, by = _box_outline(box)
        fig.add_trace(go.Scatter(
            x=by, y=bx, mode="lines", line={"color": "#222", "dash": "dash", "width": 1.2},
            name="label boxes", legendgroup="boxes", showlegend=k == 0,
            meta=_meta("overlay", None, view="bev", box=k), hoverinfo="skip"), row=1, col=1)
    fig.add_trace(go.Scatter(x=[0], y=[0], mode="markers", name="radar",
                             marker={"symbol": "triangle-up", "color": "black", "size": 11},
                             meta=_meta("overlay", None, view="bev"),
                             hovertemplate="radar at the origin<extra></extra>"), row=1, col=1)
    _layout(fig, str(o.get("title") or "overlay"), height=640)
    fig.update_xaxes(title_text="y (left) [m]", autorange="reversed", scaleanchor="y",
                     scaleratio=1, row=1, col=1)
    fig.update_xaxes(title_text="z (up) [m]", row=1, col=2)
    fig.update_yaxes(title_text="x (forward) [m]", row=1, col=1)
    return _fig_json(fig)


# ------------------------------------------------------------------- artefacts, fidelity
def _has_artefacts(gap: Mapping[str, Any]) -> bool:
    a = _section(gap, "artefacts")
    return isinstance(a.get("sim"), Mapping) and isinstance(a.get("real"), Mapping)


def _bar_label(v: Any) -> str:
    f = num(v)
    return "unknown" if f is None else f"{100 * f:.1f}"


def artefacts_figure(gap: Mapping[str, Any]) -> dict[str, Any]:
    """Three panels, as ``artefacts.png``: the share of points on a stronger return's range
    bin (where angle sidelobes would be) against its control bins; each dataset's Doppler
    histogram (a dataset without Doppler is named in the title, not drawn); the shares beyond
    the far range and below the floor."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    a = _section(gap, "artefacts")
    st = _section(a, "settings")
    far, margin = num(st.get("far_range_m")), num(st.get("below_floor_margin_m"))
    bin_mps = num(st.get("doppler_bin_mps"))
    sides = [(side, _section(a, side)) for side in ("sim", "real")]
    names = [f"{side} ({_domain(gap, side) or 'domain ?'})" for side, _ in sides]
    edges = a.get("doppler_edges_mps")
    missing = [side for side, d in sides
               if not (_numbers(edges) and isinstance(d.get("doppler"), Mapping)
                       and _histogram(edges, d["doppler"].get("fraction")))]
    moving = f"|v| > {bin_mps / 2:g} m/s" if bin_mps else "moving"
    fig = make_subplots(rows=1, cols=3, column_widths=[0.28, 0.44, 0.28],
                        horizontal_spacing=0.07, subplot_titles=(
                            "sidelobe bins vs control bins",
                            f"Doppler (moving: {moving})" + "".join(
                                f"<br>{s}: no Doppler column (not drawn)" for s in missing),
                            "range coverage and the floor"))
    for what, key, pattern in (("sidelobe bins", "sidelobe_share", ""),
                               ("control bins", "sidelobe_control_share", "/")):
        values = [d.get(key) for _, d in sides]
        fig.add_trace(go.Bar(
            x=names, y=[0.0 if num(v) is None else 100 * num(v) for v in values],
            text=[_bar_label(v) for v in values], textposition="outside", name=what,
            marker={"color": [SIDE_COLOURS[s] for s, _ in sides],
                    "pattern": {"shape": pattern, "fillmode": "overlay" if pattern else
                                "replace"},
                    "line": {"color": [SIDE_COLOURS[s] for s, _ in sides], "width": 1.5}},
            meta=_meta("artefacts", None, measure=key),
            hovertemplate=f"%{{x}}<br>{what}: %{{text}} % of points<extra></extra>"),
            row=1, col=1)
    for side, d in sides:
        if side in missing:
            continue
        dop = d["doppler"]
        med = num(dop.get("abs_median_mps"))
        trace = _stairs_trace(edges, dop["fraction"], side=side, figure="artefacts",
                              unit="m/s", xaxis="x2", yaxis="y2",
                              name=(f"{side}: moving {_pct_text(dop.get('moving_share'))}, "
                                    f"median |v| {'n/a' if med is None else f'{med:.2f}'} m/s"))
        fig.add_trace(trace, row=1, col=2)
    groups = [f"range > {'?' if far is None else f'{far:g}'} m",
              f"> {'?' if margin is None else f'{margin:g}'} m below the floor"]
    for side, d in sides:
        values = [d.get("beyond_range_share"), d.get("below_floor_share")]
        notes = ["", str(d.get("below_floor_note") or "")]
        fig.add_trace(go.Bar(
            x=groups, y=[0.0 if num(v) is None else 100 * num(v) for v in values],
            text=[_bar_label(v) for v in values], textposition="outside", name=side,
            marker={"color": SIDE_COLOURS[side]}, customdata=notes,
            meta=_meta("artefacts", side, measure="shares"),
            hovertemplate=(f"{side}, %{{x}}: %{{text}} % of points<br>%{{customdata}}"
                           "<extra></extra>")), row=1, col=3)
    _layout(fig, "radar artefacts per dataset", height=460, barmode="group")
    fig.update_yaxes(title_text="points [%]", rangemode="tozero", row=1, col=1)
    fig.update_yaxes(title_text="points per bin [%]", rangemode="tozero", row=1, col=2)
    fig.update_xaxes(title_text="Doppler [m/s]", row=1, col=2)
    fig.update_yaxes(title_text="points [%]", rangemode="tozero", row=1, col=3)
    return _fig_json(fig)


def _has_fidelity(gap: Mapping[str, Any]) -> bool:
    f = _section(gap, "fidelity")
    return isinstance(f.get("sim"), Mapping) and isinstance(f.get("real"), Mapping)


def fidelity_figure(gap: Mapping[str, Any]) -> dict[str, Any]:
    """Two panels, as ``fidelity.png``: per dataset the shares of points behind the first true
    surface and beyond 0.85 R_max and of door label boxes without points and with few; the
    median points inside a door label box."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    f = _section(gap, "fidelity")
    groups = [f"> {BEHIND_SURFACE_M:g} m behind the first surface",
              f"beyond {FAR_RANGE_FRACTION:g} R_max", "door boxes without points",
              f"door boxes < {_FEW_POINTS} points"]
    keys = ("behind_share", "beyond_share", "labels_empty", "labels_under_5")
    fig = make_subplots(rows=1, cols=2, column_widths=[0.7, 0.3], horizontal_spacing=0.08,
                        subplot_titles=("where the points are (against the true geometry) "
                                        "and the door label boxes", "the door signal"))
    for side in ("sim", "real"):
        d = _section(f, side)
        values = [d.get(k) for k in keys]
        fig.add_trace(go.Bar(
            x=groups, y=[0.0 if num(v) is None else 100 * num(v) for v in values],
            text=[_bar_label(v) for v in values], textposition="outside",
            name=f"{side} ({_domain(gap, side) or 'domain ?'})", legendgroup=side,
            marker={"color": SIDE_COLOURS[side]}, meta=_meta("fidelity", side,
                                                            measure="shares"),
            hovertemplate=f"{side}, %{{x}}: %{{text}} %<extra></extra>"), row=1, col=1)
        ppl = num(d.get("points_per_label"))
        fig.add_trace(go.Bar(
            x=[side], y=[ppl or 0.0], text=["unknown" if ppl is None else f"{ppl:.0f}"],
            textposition="outside", name=side, legendgroup=side, showlegend=False,
            marker={"color": SIDE_COLOURS[side]},
            meta=_meta("fidelity", side, measure="points_per_label"),
            hovertemplate=f"{side}: median %{{text}} points in a door label box"
                          "<extra></extra>"), row=1, col=2)
    _layout(fig, "fidelity: the points against the true geometry, and the door labels",
            height=460, barmode="group")
    fig.update_yaxes(title_text="points or boxes [%]", rangemode="tozero", row=1, col=1)
    fig.update_yaxes(title_text="points in a door label box (median)", rangemode="tozero",
                     row=1, col=2)
    return _fig_json(fig)


#: the gap report's figures by their ``gap.json["figures"]`` name, in the page's order
GAP_PLOTS: dict[str, GapPlot] = {
    "overlay": GapPlot("one frame, sim (red) over real (blue): the paper's Figure 3",
                       _has_overlay, overlay_figure),
    "points": GapPlot("points per frame", _has_points, points_figure),
    "azimuth": GapPlot("azimuth coverage", _has_azimuth, azimuth_figure),
    "range": GapPlot("range coverage", _has_range, range_figure),
    "intensity": GapPlot("intensity distributions", _has_intensity, intensity_figure),
    "artefacts": GapPlot("radar artefacts", _has_artefacts, artefacts_figure),
    "fidelity": GapPlot("fidelity against the true geometry", _has_fidelity, fidelity_figure),
}
