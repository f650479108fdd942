"""The dashboard's Plotly figures, as plain JSON (``{"data": [...], "layout": {...}}``) for the
page's ``Plotly.react``; pure functions of the statistics
(:func:`~sim2radar.experiment.stats.sweep_statistics`), the ``experiment_runs`` rows and the
``experiment_pretrain`` rows.

    ap_figure(stats, conds, metric, folders)   AP vs real-data fraction (paper Figure 4)
    delta_figure(stats, conds, metric)         paired difference to the baseline, with its
                                               simultaneous interval and the MDE
    curves_figure(runs, conds)                 learning curves: mean and band per condition and
                                               fraction, each run faint behind
    pretrain_loss_figure(rows, conds)          the pre-trainings' loss curves
    pretrain_check_figure(table, conds)        the pre-trainings' checks: held-out sim AP and
                                               zero-shot real AP, with the thresholds
    run_layout(), run_traces(run, pretraining) one run's learning curve and its
                                               pre-training's loss (the run's own view)

Every trace carries ``meta = {"role": ..., "condition": ...}``: ``mean``/``trials`` (AP),
``delta``/``delta-trials``/``mde``/``paper-delta`` (difference), ``loss``/``val_ap`` (curves),
``pretrain_loss`` (pre-training loss), ``pretrain_check`` (the checks; ``meta.measure``
``heldout``, ``zero_shot`` or ``threshold``), ``run_loss``/``run_val_ap``/``run_test_ap``/
``run_pretrain_loss`` (one run's view); the page and its tests find traces by it.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

from sim2radar.experiment.dashboard.labels import colour, metric_label, num, pct
from sim2radar.experiment.profiles import BASELINE
from sim2radar.experiment.report import condition_label
from sim2radar.experiment.stats import paper_delta

__all__ = ["ap_figure", "curves_figure", "delta_figure", "pretrain_check_figure",
           "pretrain_loss_figure", "run_layout", "run_traces"]

#: multiplicative x offset between conditions on the log fraction axis (keeps error bars apart)
DODGE = 0.035
#: Plotly's layout template of every figure
PLOTLY_TEMPLATE = "plotly_white"


def _fig_json(fig) -> dict[str, Any]:
    """A Plotly figure as plain JSON (``{"data": [...], "layout": {...}}``)."""
    return json.loads(fig.to_json())


def _empty_note(fig, text: str) -> None:
    fig.add_annotation(text=text, xref="paper", yref="paper", x=0.5, y=0.5, showarrow=False,
                       font={"size": 14, "color": "#777"})


def _fraction_axis(fractions: Sequence[float]) -> dict[str, Any]:
    ticks = [100 * f for f in fractions] or [5, 10, 25, 50, 100]
    return {"type": "log", "title": {"text": "real data [% of the train split]"},
            "tickvals": ticks, "ticktext": [f"{t:g} %" for t in ticks],
            "range": [math.log10(min(ticks)) - 0.12, math.log10(max(ticks)) + 0.12]}


def _dodge(i: int, k: int) -> float:
    return 1.0 + DODGE * (i - (k - 1) / 2)


def ap_figure(stats: Mapping[str, Any], conds: Sequence[str], metric: str,
               folders: Mapping[tuple[str, float, int], str] | None = None) -> dict[str, Any]:
    """AP vs real-data fraction (paper Figure 4): per condition a ``mean`` trace (mean ± std
    error bars) and a ``trials`` trace (every trial's value; its hover names the run folder,
    ``folders``: (condition, fraction, trial) -> folder relative to the sweep)."""
    import plotly.graph_objects as go

    cells = {(c["condition"], float(c["fraction"])): c for c in stats.get("cells", [])}
    fractions = [float(f) for f in stats.get("fractions", [])]
    fig = go.Figure()
    for i, cond in enumerate(conds):
        color, label, dx = colour(cond, conds), condition_label(cond), _dodge(i, len(conds))
        xs, ys, es, info = [], [], [], []
        tx, ty, tinfo = [], [], []
        for f in fractions:
            cell = cells.get((cond, f))
            if cell is None:
                continue
            for t, v in zip(cell.get("trials", []), cell.get("values", []), strict=False):
                tx.append(100 * f * dx)
                ty.append(v)
                tinfo.append([pct(f), t, (folders or {}).get((cond, f, int(t)), "—")])
            if cell.get("mean") is None:
                continue
            xs.append(100 * f * dx)
            ys.append(cell["mean"])
            es.append(cell.get("std") or 0.0)
            info.append([pct(f), cell.get("std"), cell.get("n"), cell.get("n_failed"),
                         cell.get("n_real_frames")])
        fig.add_trace(go.Scatter(
            x=xs, y=ys, error_y={"type": "data", "array": es, "visible": True, "thickness": 1.5,
                                 "width": 5},
            mode="lines+markers", name=label, legendgroup=cond,
            line={"color": color, "width": 2.5}, marker={"color": color, "size": 9},
            customdata=info, meta={"role": "mean", "condition": cond},
            hovertemplate=(f"<b>{html.escape(label)}</b> %{{customdata[0]}}<br>"
                           "mean %{y:.2f} ± %{customdata[1]:.2f} (std)<br>"
                           "%{customdata[2]} trial(s), %{customdata[3]} failed<br>"
                           "%{customdata[4]} real frames<extra></extra>")))
        fig.add_trace(_trial_markers(tx, ty, tinfo, cond, label, color, name=f"{label}: trials",
                                     role="trials", value="%{y:.2f}<br>run folder "
                                                          "%{customdata[2]}"))
    fig.update_layout(
        template=PLOTLY_TEMPLATE, height=440, margin={"l": 60, "r": 20, "t": 50, "b": 55},
        title={"text": f"{metric_label(metric)} vs real data (mean ± std, every trial)"},
        xaxis=_fraction_axis(fractions), yaxis={"title": {"text": f"{metric_label(metric)} [%]"},
                                                "rangemode": "tozero"},
        legend={"orientation": "h", "y": -0.2}, uirevision="keep")
    if not any(c.get("mean") is not None for c in stats.get("cells", [])):
        _empty_note(fig, "no finished run yet")
    return _fig_json(fig)


def _interval(comp: Mapping[str, Any], key: str) -> tuple[float | None, float | None]:
    """``comp[key]`` as (lo, hi), None for an absent or undefined bound."""
    lo, hi = (list(comp.get(key) or []) + [None, None])[:2]
    return num(lo), num(hi)


def _ci_text(lo: float | None, hi: float | None) -> str:
    return "n/a" if lo is None or hi is None else f"[{lo:+.2f}, {hi:+.2f}]"


def delta_figure(stats: Mapping[str, Any], conds: Sequence[str], metric: str,
                  ) -> dict[str, Any]:
    """Paired difference to the baseline per fraction: per non-baseline condition a ``delta``
    trace (mean difference with an error bar), a ``delta-trials`` trace and an ``mde`` trace
    (the minimum detectable effect at 80 % power: a true Δ below it is more likely than not to
    be missed); one ``paper-delta`` trace (the paper's Table 1 Δ).

    The error bar is the comparison's simultaneous ``1 - alpha`` interval
    (``t_ci_simultaneous``: the ``1 - alpha / m`` Student-t interval over the condition's m
    fractions, the one the Holm verdict agrees with); a ``stats.json`` written before it
    existed gets the unadjusted ``t_ci``, and the axis title and hover say which is drawn. The
    hover gives both.
    """
    import plotly.graph_objects as go

    level = f"{100 * (1 - float(stats.get('alpha', 0.05))):g} %"
    comparisons = list(stats.get("comparisons", []))
    simultaneous = any("t_ci_simultaneous" in c for c in comparisons)
    bars = (f"simultaneous {level} CI, Holm family" if simultaneous
            else f"{level} t-interval, unadjusted")
    power = float((stats.get("power") or {}).get("power", 0.8))
    fractions = [float(f) for f in stats.get("fractions", [])]
    others = [c for c in conds if c != BASELINE]
    fig = go.Figure()
    fig.add_hline(y=0, line={"color": "#444", "width": 1, "dash": "dot"})
    for i, cond in enumerate(others):
        color, label, dx = colour(cond, conds), condition_label(cond), _dodge(i, len(others))
        comps = [c for c in comparisons if c["condition"] == cond]
        xs, ys, up, down, info = [], [], [], [], []
        tx, ty, tinfo = [], [], []
        mx, my, minfo = [], [], []
        for comp in comps:
            f = float(comp["fraction"])
            for t, d in zip(comp.get("trials", []), comp.get("differences", []), strict=False):
                tx.append(100 * f * dx)
                ty.append(d)
                tinfo.append([pct(f), t])
            mde = num(comp.get("mde"))
            if mde is not None:
                mx.append(100 * f)
                my.append(mde)
                minfo.append([pct(f), comp.get("n_pairs"), comp.get("mde_alpha")])
            m = comp.get("mean_diff")
            if m is None:
                continue
            lo, hi = _interval(comp, "t_ci_simultaneous" if simultaneous else "t_ci")
            xs.append(100 * f * dx)
            ys.append(m)
            up.append(hi - m if hi is not None else 0.0)
            down.append(m - lo if lo is not None else 0.0)
            ci = _ci_text(lo, hi)
            unadjusted = _ci_text(*_interval(comp, "t_ci"))
            boot = _ci_text(*_interval(comp, "bootstrap_ci"))
            p = comp.get("p_holm")
            share = comp.get("p_improved")
            s_lo, s_hi = (comp.get("p_improved_ci") or [None, None])[:2]
            info.append([pct(f), ci, boot, "n/a" if p is None else f"{p:.3g}",
                         f"{comp.get('k_improved', 0)}/{comp.get('n_pairs', 0)}",
                         comp.get("verdict", ""),
                         "n/a" if mde is None else f"{mde:.2f}",
                         "n/a" if share is None else
                         f"{100 * share:.0f} % [{100 * s_lo:.0f}, {100 * s_hi:.0f}]",
                         unadjusted])
        fig.add_trace(go.Scatter(
            x=xs, y=ys, mode="lines+markers", name=f"{label} − {condition_label(BASELINE)}",
            legendgroup=cond, line={"color": color, "width": 2.5},
            marker={"color": color, "size": 9},
            error_y={"type": "data", "symmetric": False, "array": up, "arrayminus": down,
                     "visible": True, "thickness": 1.5, "width": 5},
            customdata=info, meta={"role": "delta", "condition": cond},
            hovertemplate=(f"<b>{html.escape(label)}</b> %{{customdata[0]}}<br>"
                           f"Δ %{{y:+.2f}}, {bars} %{{customdata[1]}}<br>"
                           + (f"unadjusted {level} t-interval %{{customdata[8]}}<br>"
                              if simultaneous else "") +
                           f"MDE ({100 * power:g} % power) %{{customdata[6]}}<br>"
                           "bootstrap (reference) %{customdata[2]}<br>"
                           "p (Holm) %{customdata[3]}, improved in %{customdata[4]} "
                           "(P %{customdata[7]})<br>"
                           "%{customdata[5]}<extra></extra>")))
        fig.add_trace(_trial_markers(tx, ty, tinfo, cond, label, color,
                                     name=f"{label}: per-trial Δ", role="delta-trials",
                                     value="Δ %{y:+.2f}"))
        fig.add_trace(go.Scatter(
            x=mx, y=my, mode="lines+markers", name=f"{label}: MDE ({100 * power:g} % power)",
            legendgroup=cond, line={"color": color, "width": 1.2, "dash": "dash"},
            marker={"color": color, "size": 6, "symbol": "triangle-up-open"},
            customdata=minfo, meta={"role": "mde", "condition": cond},
            hovertemplate=(f"{html.escape(label)} %{{customdata[0]}}: smallest Δ detectable "
                           f"with {100 * power:g} % power %{{y:.2f}}<br>(%{{customdata[1]}} "
                           "pairs, level %{customdata[2]:.3g})<extra></extra>")))
    if others:
        px = [100 * f for f in fractions if paper_delta(f) is not None]
        py = [paper_delta(f) for f in fractions if paper_delta(f) is not None]
        fig.add_trace(go.Scatter(
            x=px, y=py, mode="markers", name="paper Table 1 Δ (Sim Pretrain)",
            marker={"color": "#222", "size": 10, "symbol": "x-thin-open",
                    "line": {"width": 2, "color": "#222"}},
            meta={"role": "paper-delta", "condition": None},
            hovertemplate="paper Table 1: Δ %{y:+.1f} at %{x:g} %<extra></extra>"))
    fig.update_layout(
        template=PLOTLY_TEMPLATE, height=430, margin={"l": 60, "r": 20, "t": 65, "b": 55},
        title={"text": f"Δ {metric_label(metric)} vs baseline, paired by trial<br><sup>mean; "
                       f"bars: {bars}; dashed: MDE at {100 * power:g} % power</sup>"},
        xaxis=_fraction_axis(fractions),
        yaxis={"title": {"text": f"Δ AP [points] (bars: {bars})"}},
        legend={"orientation": "h", "y": -0.2}, uirevision="keep")
    if not others:
        _empty_note(fig, "no condition besides the baseline in this sweep")
    elif not any(c.get("n_pairs") for c in stats.get("comparisons", [])):
        _empty_note(fig, "no paired runs yet (a pair needs the baseline and the condition "
                         "of the same trial)")
    return _fig_json(fig)


def _trial_markers(tx, ty, tinfo, cond: str, label: str, color: str, *, name: str, role: str,
                   value: str):
    """One open marker per trial (``tinfo``: [fraction label, trial]) beside a cell's mean."""
    import plotly.graph_objects as go

    return go.Scatter(
        x=tx, y=ty, mode="markers", name=name, legendgroup=cond, showlegend=False,
        marker={"color": color, "size": 6, "opacity": 0.45, "symbol": "circle-open",
                "line": {"width": 1.5}},
        customdata=tinfo, meta={"role": role, "condition": cond},
        hovertemplate=(f"{html.escape(label)} %{{customdata[0]}}, trial %{{customdata[1]}}"
                       f"<br>{value}<extra></extra>"))


def _rgba(hex_colour: str, alpha: float) -> str:
    """``#rrggbb`` as ``rgba(r, g, b, alpha)`` (a band's fill)."""
    h = hex_colour.lstrip("#")
    if len(h) != 6:
        return hex_colour
    r, g, b = (int(h[i:i + 2], 16) for i in (0, 2, 4))
    return f"rgba({r}, {g}, {b}, {alpha})"


def curves_figure(runs: Sequence[Mapping[str, Any]], conds: Sequence[str]) -> dict[str, Any]:
    """Learning curves, grouped: per condition and fraction the mean over its trials (a
    ``loss_mean`` / ``val_ap_mean`` line, one legend entry per condition) inside the band of
    its trials (min to max, ``*_band``), and each run's own curve faint behind them (``loss``
    / ``val_ap``: a diverged run stays visible). Every trace's ``meta`` names its condition
    and fraction (and a run's trial), so the page shows only what the runs table's filters
    let through. x is the optimiser step at the end of each epoch (``epoch x steps /
    epochs``): runs of different fractions have different epoch lengths."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    fig = make_subplots(rows=1, cols=2, horizontal_spacing=0.08,
                        subplot_titles=("training loss (mean per epoch)",
                                        "validation 3D AP R40 @ IoU 0.3 [%]"))
    ordered = sorted(runs, key=lambda r: (conds.index(r["condition"]) if r.get("condition")
                                          in conds else len(conds), r.get("fraction") or 0,
                                          r.get("trial") or 0))
    groups: dict[tuple[str, float], dict[str, dict[int, list[float]]]] = {}
    n_curves = 0
    for r in ordered:
        cond, fraction = str(r.get("condition")), float(r.get("fraction") or 0)
        epochs, loss = r.get("history_epoch") or [], r.get("history_loss") or []
        v_ep, v_ap = r.get("history_val_epoch") or [], r.get("history_val_ap") or []
        if not (epochs and loss) and not (v_ep and v_ap):
            continue
        color, label = colour(cond, conds), condition_label(cond)
        run = (f"{html.escape(label)} {pct(fraction)}, "
               f"trial {r.get('trial')} (seed {r.get('seed')})")
        n_ep, n_steps = int(r.get("epochs") or 0), int(r.get("steps") or 0)
        per_epoch = n_steps / n_ep if n_ep > 0 and n_steps > 0 else 1.0
        epochs = [round(e * per_epoch) for e in epochs]
        v_ep = [round(e * per_epoch) for e in v_ep]
        cell = groups.setdefault((cond, fraction), {"loss": {}, "val_ap": {}})
        for col, (x, y, role, fmt) in enumerate(((epochs, loss, "loss", ".4f"),
                                                 (v_ep, v_ap, "val_ap", ".2f")), start=1):
            if not (x and y):
                continue
            for xi, yi in zip(x, y, strict=False):
                if num(yi) is not None:
                    cell[role].setdefault(int(xi), []).append(float(yi))
            fig.add_trace(go.Scatter(
                x=list(x), y=[num(v) for v in y], mode="lines", name=label,
                legendgroup=cond, showlegend=False, line={"color": color, "width": 0.8},
                opacity=0.35,
                meta={"role": role, "condition": cond, "fraction": fraction,
                      "trial": r.get("trial"), "run_key": r.get("run_key")},
                hovertemplate=f"{run}<br>step %{{x}}: %{{y:{fmt}}}<extra></extra>"),
                row=1, col=col)
            n_curves += 1
    shown: set[str] = set()
    for (cond, fraction), cell in groups.items():
        color, label = colour(cond, conds), condition_label(cond)
        for col, role in enumerate(("loss", "val_ap"), start=1):
            points = sorted(cell[role].items())
            if not points:
                continue
            x = [p[0] for p in points]
            lo, hi = [min(p[1]) for p in points], [max(p[1]) for p in points]
            mean = [sum(p[1]) / len(p[1]) for p in points]
            n = max(len(p[1]) for p in points)
            meta = {"condition": cond, "fraction": fraction, "trials": n}
            fig.add_trace(go.Scatter(x=x, y=hi, mode="lines", line={"width": 0},
                                     showlegend=False, hoverinfo="skip", legendgroup=cond,
                                     meta={"role": f"{role}_band", **meta}), row=1, col=col)
            fig.add_trace(go.Scatter(x=x, y=lo, mode="lines", line={"width": 0},
                                     fill="tonexty", fillcolor=_rgba(color, 0.15),
                                     showlegend=False, hoverinfo="skip", legendgroup=cond,
                                     meta={"role": f"{role}_band", **meta}), row=1, col=col)
            fig.add_trace(go.Scatter(
                x=x, y=mean, mode="lines+markers" if len(x) < 3 else "lines", name=label,
                legendgroup=cond, showlegend=cond not in shown,
                line={"color": color, "width": 2.0}, marker={"size": 4},
                meta={"role": f"{role}_mean", **meta},
                hovertemplate=(f"{html.escape(label)} {pct(fraction)}: mean of {n} trial(s)"
                               "<br>step %{x}: %{y:.3f}<extra></extra>")), row=1, col=col)
            shown.add(cond)
    for col in (1, 2):
        fig.update_xaxes(title_text="optimiser step", rangemode="tozero", row=1, col=col)
    fig.update_layout(template=PLOTLY_TEMPLATE, height=380,
                      margin={"l": 60, "r": 20, "t": 50, "b": 55},
                      legend={"orientation": "h", "y": -0.25}, uirevision="keep")
    if not n_curves:
        _empty_note(fig, "no learning curve yet")
    return _fig_json(fig)


def _palette(conds: Sequence[str], more: Sequence[str]) -> list[str]:
    """``conds`` then the conditions of ``more`` not among them (so :func:`colour` knows
    every condition a pre-training names)."""
    return list(dict.fromkeys([*conds, *more]))


def pretrain_loss_figure(rows: Sequence[Mapping[str, Any]], conds: Sequence[str],
                         ) -> dict[str, Any]:
    """The pre-trainings' loss curves: one ``pretrain_loss`` trace per pre-training that did
    not fail and has a loss history (``experiment_pretrain`` rows: mean training loss per
    epoch against the epoch), coloured by the first condition that loads it, grouped in the
    legend by the dataset role it trained on (one legend entry per role)."""
    import plotly.graph_objects as go

    palette = _palette(conds, [str(c) for r in rows for c in (r.get("conditions") or [])])
    fig = go.Figure()
    shown: set[str] = set()
    for r in sorted(rows, key=lambda r: (str(r.get("sim_role")), str(r.get("pretrain_id")))):
        epochs, loss = list(r.get("history_epoch") or []), list(r.get("history_loss") or [])
        if r.get("status") == "failed" or not (epochs and loss):
            continue
        role = str(r.get("sim_role"))
        names = [str(c) for c in (r.get("conditions") or [])]
        first = names[0] if names else BASELINE
        labels = ", ".join(condition_label(c) for c in names) or "no condition"
        what = (f"{html.escape(str(r.get('pretrain_id')))} ({html.escape(role)} data; "
                f"{html.escape(labels)})")
        fig.add_trace(go.Scatter(
            x=[int(e) for e in epochs], y=[num(v) for v in loss],
            mode="lines+markers" if len(epochs) < 3 else "lines",
            name=f"pre-trained on {role} ({labels})", legendgroup=role,
            showlegend=role not in shown, line={"color": colour(first, palette), "width": 1.4},
            marker={"size": 4}, opacity=0.8,
            meta={"role": "pretrain_loss", "condition": first, "sim_role": role,
                  "pretrain_id": r.get("pretrain_id")},
            hovertemplate=f"{what}<br>epoch %{{x}}: loss %{{y:.4f}}<extra></extra>"))
        shown.add(role)
    fig.update_layout(
        template=PLOTLY_TEMPLATE, height=360, margin={"l": 60, "r": 20, "t": 50, "b": 55},
        title={"text": "pre-training loss (mean per epoch), one curve per pre-training"},
        xaxis={"title": {"text": "epoch"}, "rangemode": "tozero"},
        yaxis={"title": {"text": "training loss"}},
        legend={"orientation": "h", "y": -0.25}, uirevision="keep")
    if not fig.data:
        _empty_note(fig, "no pre-training loss curve yet")
    return _fig_json(fig)


#: the checks of :func:`pretrain_check_figure`: (key in a pre-training table row, legend name,
#: marker symbol, x offset from the condition's tick)
_CHECKS = (("heldout", "held-out sim AP", "circle", -0.15),
           ("zero_shot", "zero-shot real AP", "diamond-open", 0.15))


def pretrain_check_figure(table: Mapping[str, Any], conds: Sequence[str]) -> dict[str, Any]:
    """The pre-trainings' checks per condition (a strip plot): every pre-training's held-out
    sim AP (filled circles, left of the condition's tick) and zero-shot real AP (open
    diamonds, right), each a ``pretrain_check`` trace with ``meta.measure`` ``heldout`` /
    ``zero_shot``; where the profile declares a learnability threshold for the condition, a
    dashed ``threshold`` line across its held-out points at that AP.

    Parameters
    ----------
    table : :func:`~sim2radar.experiment.learnability.pretraining_table`'s dict (APs in %).
    conds : the dashboard's conditions (colours).
    """
    import plotly.graph_objects as go

    rows = [r for r in table.get("rows", []) if r.get("status") != "failed"]
    thresholds = table.get("thresholds") or {}
    names = [str(s["condition"]) for s in table.get("summary", [])] or list(
        dict.fromkeys(str(c) for r in rows for c in r.get("conditions") or []))
    palette = _palette(conds, names)
    fig = go.Figure()
    for i, cond in enumerate(names):
        color, label = colour(cond, palette), condition_label(cond)
        mine = [r for r in rows if cond in (r.get("conditions") or [])]
        for key, what, symbol, offset in _CHECKS:
            pts = [r for r in mine if num(r.get(key)) is not None]
            spread = [0.08 * (2 * k / (len(pts) - 1) - 1) if len(pts) > 1 else 0.0
                      for k in range(len(pts))]
            fig.add_trace(go.Scatter(
                x=[i + offset + dx for dx in spread], y=[num(r[key]) for r in pts],
                mode="markers", name=f"{label}: {what}", legendgroup=cond,
                marker={"color": color, "size": 10, "symbol": symbol, "line": {"width": 1.5}},
                customdata=[[str(r.get("id")), r.get("trial"), _met(r, cond)] for r in pts],
                meta={"role": "pretrain_check", "condition": cond, "measure": key},
                hovertemplate=(f"<b>{html.escape(label)}</b> %{{customdata[0]}} (trial "
                               f"%{{customdata[1]}})<br>{what} %{{y:.2f}}"
                               + ("<br>threshold %{customdata[2]}" if key == "heldout"
                                  else "") + "<extra></extra>")))
        thr = num(thresholds.get(cond))
        if thr is not None:
            centre = i + _CHECKS[0][3]  # across the held-out points only: its threshold
            fig.add_trace(go.Scatter(
                x=[centre - 0.17, centre + 0.17], y=[thr, thr], mode="lines",
                name=f"{label}: threshold {thr:g} (held-out sim AP)", legendgroup=cond,
                line={"color": color, "width": 2, "dash": "dash"},
                meta={"role": "pretrain_check", "condition": cond, "measure": "threshold"},
                hovertemplate=(f"{html.escape(label)}: pre-registered learnability threshold "
                               f"{thr:g} on the held-out sim AP<extra></extra>")))
    fig.update_layout(
        template=PLOTLY_TEMPLATE, height=380, margin={"l": 60, "r": 20, "t": 50, "b": 55},
        title={"text": "what each pre-training learned before fine-tuning: 3D AP R40 @ IoU 0.3 "
                       "(dashed: learnability threshold)"},
        xaxis={"tickvals": list(range(len(names))),
               "ticktext": [condition_label(c) for c in names],
               "range": [-0.6, max(len(names), 1) - 0.4], "zeroline": False},
        yaxis={"title": {"text": "AP [%]"}, "rangemode": "tozero"},
        legend={"orientation": "h", "y": -0.2}, uirevision="keep")
    if not any(t.y for t in fig.data if t.meta["measure"] != "threshold"):
        _empty_note(fig, "no pre-training checked yet")
    return _fig_json(fig)


def _met(row: Mapping[str, Any], cond: str) -> str:
    """``met`` / ``not met`` / ``none declared`` of a pre-training row for ``cond``."""
    met = (row.get("met") or {}).get(cond)
    return "none declared" if met is None else "met" if met else "not met"


def run_layout() -> dict[str, Any]:
    """The layout of a run's own figure (:func:`run_traces` fill it): three panels side by
    side, the fine-tuning loss per epoch, the validation and final test AP per epoch, and the
    loss of the pre-training it loaded. One layout for every run (a figure per run, built with
    Plotly's objects, took seconds for a sweep of a hundred runs)."""
    from plotly.subplots import make_subplots

    fig = make_subplots(rows=1, cols=3, horizontal_spacing=0.08, subplot_titles=(
        "fine-tuning loss (mean per epoch)", "3D AP R40 @ IoU 0.3 [%]",
        "its pre-training's loss"))
    for col in (1, 2, 3):
        fig.update_xaxes(title_text="epoch", rangemode="tozero", row=1, col=col)
    fig.update_layout(template=PLOTLY_TEMPLATE, height=340,
                      margin={"l": 55, "r": 20, "t": 45, "b": 50},
                      legend={"orientation": "h", "y": -0.28})
    return _fig_json(fig)["layout"]


def run_traces(run: Mapping[str, Any], pretraining: Mapping[str, Any] | None = None,
               ) -> list[dict[str, Any]]:
    """One run's learning curve as plain Plotly traces for :func:`run_layout`: the mean
    training loss per epoch (``run_loss``, first panel), the validation 3D AP R40 @ IoU 0.3
    at the epochs it was measured (``run_val_ap``) and the final test-split AP of the same
    metric at the last epoch (``run_test_ap``: another split, a star) in the second, the loss
    per epoch of the pre-training it loaded (``run_pretrain_loss``) in the third.

    Parameters
    ----------
    run : one ``experiment_runs`` row.
    pretraining : the ``experiment_pretrain`` row of its pre-training, or None.
    """
    cond = str(run.get("condition"))
    col = colour(cond, [cond])
    epochs = [int(e) for e in run.get("history_epoch") or []]
    loss = [num(v) for v in run.get("history_loss") or []]
    v_ep = [int(e) for e in run.get("history_val_epoch") or []]
    v_ap = [num(v) for v in run.get("history_val_ap") or []]
    traces = [
        {"type": "scatter", "x": epochs, "y": loss, "xaxis": "x", "yaxis": "y",
         "mode": "lines+markers" if len(epochs) < 30 else "lines", "name": "training loss",
         "line": {"color": col, "width": 2}, "marker": {"size": 4},
         "meta": {"role": "run_loss", "condition": cond},
         "hovertemplate": "epoch %{x}: loss %{y:.4f}<extra></extra>"},
        {"type": "scatter", "x": v_ep, "y": v_ap, "xaxis": "x2", "yaxis": "y2",
         "mode": "lines+markers", "name": "validation AP (val split)",
         "line": {"color": col, "width": 2}, "marker": {"size": 6},
         "meta": {"role": "run_val_ap", "condition": cond},
         "hovertemplate": "epoch %{x}: val AP %{y:.2f}<extra></extra>"},
    ]
    test = num(run.get("ap_3d_r40_iou03"))
    if test is not None:
        last = max([*epochs, *v_ep] or [int(run.get("epochs") or 0)])
        traces.append({
            "type": "scatter", "x": [last], "y": [test], "xaxis": "x2", "yaxis": "y2",
            "mode": "markers", "name": "final AP (test split)",
            "marker": {"color": "#222", "size": 11, "symbol": "star"},
            "meta": {"role": "run_test_ap", "condition": cond},
            "hovertemplate": "final, test split: %{y:.2f}<extra></extra>"})
    if pretraining is not None:
        p_ep = [int(e) for e in pretraining.get("history_epoch") or []]
        traces.append({
            "type": "scatter", "x": p_ep,
            "y": [num(v) for v in pretraining.get("history_loss") or []],
            "xaxis": "x3", "yaxis": "y3",
            "mode": "lines+markers" if len(p_ep) < 30 else "lines",
            "name": f"pre-training loss ({html.escape(str(pretraining.get('pretrain_id')))})",
            "line": {"color": "#555", "width": 2, "dash": "dot"}, "marker": {"size": 4},
            "meta": {"role": "run_pretrain_loss", "condition": cond,
                     "pretrain_id": pretraining.get("pretrain_id")},
            "hovertemplate": "pre-training epoch %{x}: loss %{y:.4f}<extra></extra>"})
    return traces
