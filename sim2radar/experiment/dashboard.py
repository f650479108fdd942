"""The sweep dashboard: one self-contained HTML page per sweep folder, and a live view of it.

    load_sweep(folder) -> SweepData          read the sweep folder (explicit I/O, path given)
    dashboard_data(sweep) -> dict            what the page shows, JSON-able (pure)
    render_html(data, live=False) -> str     the page: Plotly's JS and the data inline (pure)
    write_dashboard(folder, out_path)        the three above, written atomically
    serve_dashboard(folder, port=0)          the live page on 127.0.0.1: ``/`` and ``/data.json``

The page works offline: Plotly's bundle, the data and the sim–real gap PNGs (as ``data:`` URIs)
are inline, and a Content-Security-Policy in the page forbids loading anything else. The live
page polls ``data.json`` every few seconds and re-renders in place (``Plotly.react``, rebuilt
tables), so runs appear as the sweep finishes them, without a reload.

What the sweep folder holds (written by ``flows/run_experiment.py`` and ``sim2radar demo``)::

    runs.parquet      one ``experiment_runs`` row per training run (storage/schemas.py)
    sweep.json        profile, conditions, fractions, trials, metric, datasets (+ domain),
                      provenance (versions, code, configs)          optional: banner "unknown"
    stats.json        sim2radar.experiment.stats.sweep_stats output  optional: recomputed
    generation.json   {"datasets": [{name, role, scenes_ok, ...}]}   optional
    gap/gap.json      sim2radar gap's report, PNGs beside it          optional
    progress.json     {"total_runs", "finished", "failed", "running", "updated_at"}  optional

Plot traces carry ``meta = {"role": ..., "condition": ...}``; the count rule the browser test
checks: the AP figure has exactly one ``"mean"`` trace and one ``"trials"`` trace per condition
of :func:`dashboard_data`'s ``conditions`` (empty where a condition has no finished run yet).
The difference figure adds, per non-baseline condition, an ``"mde"`` trace (the minimum
detectable effect per fraction) and one ``"paper-delta"`` trace (the paper's Table 1 Δ).

Every number leads back to its run: the runs table has each run's folder relative to the sweep
(``run_folder``), the trial points' hover names it, and the page filters and groups the runs
by condition, fraction and trial and downloads the rows it shows as CSV or JSON (built in the
page: no request).
"""

from __future__ import annotations

import base64
import dataclasses
import html
import ipaddress
import json
import math
import os
import posixpath
import threading
from collections.abc import Mapping, Sequence
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

from sim2radar.experiment.profiles import BASELINE, CONDITIONS
from sim2radar.experiment.report import (
    UNDECLARED,
    condition_label,
    detectability_sentences,
    domain_kind,
    results_table_rows,
)
from sim2radar.experiment.stats import AP_METRICS, DEFAULT_METRIC, paper_delta, sweep_stats

__all__ = [
    "FILES",
    "POLL_S",
    "run_folder",
    "DashboardServer",
    "SweepData",
    "SweepFolderError",
    "dashboard_data",
    "load_sweep",
    "render_html",
    "serve_dashboard",
    "allowed_host",
    "write_dashboard",
]

#: files of a sweep folder the dashboard reads, by role
FILES = {"runs": "runs.parquet", "sweep": "sweep.json", "stats": "stats.json",
         "generation": "generation.json", "gap": "gap/gap.json", "progress": "progress.json"}
#: seconds between the live page's polls of ``data.json``
POLL_S = 3.0
#: PNG file signature (PNG spec, §5.2)
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: colours of conditions outside the registry (profiles.CONDITIONS holds the known ones')
_MORE_COLORS = ("#ff7f0e", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")
#: multiplicative x offset between conditions on the log fraction axis (keeps error bars apart)
_DODGE = 0.035
_PLOTLY_TEMPLATE = "plotly_white"


class SweepFolderError(ValueError):
    """A sweep folder or one of its files cannot be read; the message names the file and the
    fix."""


@dataclasses.dataclass(frozen=True)
class SweepData:
    """Everything read from one sweep folder.

    Attributes
    ----------
    folder : Path — the sweep folder.
    runs : list of dict — ``experiment_runs`` rows, in file order (empty: no run finished yet).
    sweep : dict or None — ``sweep.json``.
    stats : dict or None — the statistics (:func:`~sim2radar.experiment.stats.sweep_stats`'s
        structure): ``stats.json`` when it matches the runs, else recomputed from ``runs``.
    stats_source : str — where ``stats`` came from, one line for the page.
    generation : dict or None — ``generation.json``.
    gap : dict or None — ``gap/gap.json``.
    gap_images : dict[str, str] — figure name -> ``data:image/png;base64,...`` of the PNGs
        that ``gap.json`` names and that exist.
    progress : dict or None — ``progress.json``.
    warnings : list of str — what was missing or ignored, one line each.
    """

    folder: Path
    runs: list[dict[str, Any]]
    sweep: dict[str, Any] | None = None
    stats: dict[str, Any] | None = None
    stats_source: str = ""
    generation: dict[str, Any] | None = None
    gap: dict[str, Any] | None = None
    gap_images: dict[str, str] = dataclasses.field(default_factory=dict)
    progress: dict[str, Any] | None = None
    warnings: list[str] = dataclasses.field(default_factory=list)


# ---------------------------------------------------------------------------------------------
# Reading a sweep folder (explicit I/O: the folder is given)
# ---------------------------------------------------------------------------------------------
_FIXES = {
    "sweep": "rerun `sim2radar sweep` with the same name to rewrite it, or delete it",
    "stats": "delete it: the dashboard recomputes the statistics from runs.parquet",
    "generation": "delete it or rewrite it as {\"datasets\": [...]}",
    "gap": "rerun `sim2radar gap SIM REAL --out <sweep>/gap`, or delete the gap folder",
    "progress": "delete it: the dashboard counts finished runs from runs.parquet",
}


def _read_json(folder: Path, role: str) -> dict[str, Any] | None:
    path = folder / FILES[role]
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise SweepFolderError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno}, "
                               f"column {exc.colno}); {_FIXES[role]}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SweepFolderError(f"{path}: cannot be read ({exc}); {_FIXES[role]}") from None
    if not isinstance(doc, dict):
        raise SweepFolderError(f"{path}: expected a JSON object, found {type(doc).__name__}; "
                               f"{_FIXES[role]}")
    return doc


def _require(doc: Mapping[str, Any], keys: Sequence[str], path: Path, role: str,
             types: type | tuple[type, ...] = list) -> None:
    for key in keys:
        if not isinstance(doc.get(key), types):
            raise SweepFolderError(f"{path}: field {key!r} is missing or not a "
                                   f"{getattr(types, '__name__', 'list')}; {_FIXES[role]}")


def _read_runs(folder: Path) -> list[dict[str, Any]]:
    import pyarrow.parquet as pq

    from sim2radar.storage import get_schema

    path = folder / FILES["runs"]
    try:
        table = pq.read_table(path)
    except Exception as exc:  # pyarrow raises ArrowInvalid / OSError for a damaged file
        raise SweepFolderError(f"{path}: not a readable Parquet file ({exc}); rerun "
                               "`sim2radar sweep` with the same name to rewrite it") from None
    try:
        table = get_schema("experiment_runs").validate(table)
    except ValueError as exc:
        raise SweepFolderError(f"{path}: {exc}") from None
    return table.to_pylist()


def _png_data_uri(path: Path) -> str | None:
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if not data.startswith(_PNG_MAGIC):
        return None
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _stats_matches(stats: Mapping[str, Any], runs: Sequence[Mapping[str, Any]]) -> bool:
    """True if ``stats`` counts exactly the runs of its conditions (not written before a run
    was added)."""
    conds = set(stats.get("conditions", []))
    counted = sum(int(c.get("n", 0)) + int(c.get("n_failed", 0)) for c in stats["cells"])
    return counted == sum(r.get("condition") in conds for r in runs)


def _conditions(sweep: Mapping[str, Any] | None, runs: Sequence[Mapping[str, Any]]) -> list[str]:
    """Planned conditions (sweep.json) then any others found in the runs, baseline first."""
    planned = list((sweep or {}).get("conditions") or [])
    found = [c for c in CONDITIONS if any(r.get("condition") == c for r in runs)]
    found += sorted({str(r["condition"]) for r in runs} - set(CONDITIONS))
    conds = list(dict.fromkeys([*planned, *found]))
    return [BASELINE, *(c for c in conds if c != BASELINE)] if BASELINE in conds else conds


def load_sweep(folder: str | os.PathLike, *, require_runs: bool = True) -> SweepData:
    """Read a sweep folder (see the module docstring for its files).

    Parameters
    ----------
    folder : the sweep folder.
    require_runs : refuse a folder without ``runs.parquet``; when False, a folder with only
        ``sweep.json`` (a sweep whose first run has not finished) reads as 0 runs.

    Returns
    -------
    SweepData — with ``stats`` from ``stats.json`` when it counts the same runs as
    ``runs.parquet``, otherwise computed from the runs (a sweep still running has no
    ``stats.json``; one that was resumed may have a stale one).

    Raises
    ------
    SweepFolderError (a ValueError) — a missing folder or file, a malformed file; the message
    names the file and the fix.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise SweepFolderError(f"{folder}: no such sweep folder; give the folder of a sweep "
                               "(e.g. out/sweeps/demo) or its name under --root")
    runs_path = folder / FILES["runs"]
    sweep = _read_json(folder, "sweep")
    if runs_path.is_file():
        runs = _read_runs(folder)
    elif require_runs or sweep is None:
        what = ("the sweep has not finished a run yet" if sweep is not None
                else "this is not a sweep folder (no sweep.json either)")
        raise SweepFolderError(f"{runs_path}: not found ({what}); run `sim2radar sweep SIM REAL "
                               "--name NAME` to fill it, or watch a starting sweep with "
                               "`sim2radar dashboard SWEEP --serve`")
    else:
        runs = []
    warnings: list[str] = []
    if sweep is None:
        warnings.append(f"{folder / FILES['sweep']} not found: the datasets, their domain and "
                        "the provenance are unknown")

    stats = _read_json(folder, "stats")
    stats_source = f"{FILES['stats']}"
    if stats is not None:
        _require(stats, ("cells", "comparisons", "conditions", "fractions"),
                 folder / FILES["stats"], "stats")
        if not _stats_matches(stats, runs):
            stats = None
            stats_source = (f"computed from {FILES['runs']} ({FILES['stats']} counts other runs: "
                            "written before the latest runs finished)")
    else:
        stats_source = f"computed from {FILES['runs']} ({FILES['stats']} not written yet)"
    if stats is None:
        metric = str((sweep or {}).get("metric") or DEFAULT_METRIC)
        if metric not in AP_METRICS:
            raise SweepFolderError(f"{folder / FILES['sweep']}: field 'metric' is {metric!r}, "
                                   f"not one of {list(AP_METRICS)}; {_FIXES['sweep']}")
        try:
            stats = sweep_stats(runs, metric, conditions=_conditions(sweep, runs))
        except ValueError as exc:
            raise SweepFolderError(f"{runs_path}: {exc}") from None

    generation = _read_json(folder, "generation")
    if generation is not None:
        _require(generation, ("datasets",), folder / FILES["generation"], "generation")
    progress = _read_json(folder, "progress")

    gap = _read_json(folder, "gap")
    images: dict[str, str] = {}
    if gap is not None:
        figures = gap.get("figures") or {}
        if not isinstance(figures, dict):
            raise SweepFolderError(f"{folder / FILES['gap']}: field 'figures' is not an object; "
                                   f"{_FIXES['gap']}")
        gap_dir = (folder / FILES["gap"]).parent
        for name, file in figures.items():
            # names only: a gap.json must not pull files from elsewhere into the page
            if not isinstance(file, str) or Path(file).name != file:
                warnings.append(f"{folder / FILES['gap']}: figure {name!r} ignored "
                                f"({file!r} is not a file name in the gap folder)")
                continue
            uri = _png_data_uri(gap_dir / file)
            if uri is None:
                warnings.append(f"{gap_dir / file}: missing or not a PNG; figure {name!r} "
                                "not shown")
            else:
                images[str(name)] = uri
    return SweepData(folder=folder, runs=runs, sweep=sweep, stats=stats,
                     stats_source=stats_source, generation=generation, gap=gap,
                     gap_images=images, progress=progress, warnings=warnings)


# ---------------------------------------------------------------------------------------------
# What the page shows (pure)
# ---------------------------------------------------------------------------------------------
def _clean(obj: Any) -> Any:
    """JSON-able copy: NaN/inf -> None, tuples -> lists, keys -> str."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if obj is None or isinstance(obj, str | bool | int):
        return obj
    if hasattr(obj, "item"):  # numpy scalar
        return _clean(obj.item())
    return str(obj)


def _num(v: Any) -> float | None:
    if v is None or isinstance(v, bool):
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _pct(fraction: float) -> str:
    return f"{100 * fraction:g} %"


def _metric_label(metric: str) -> str:
    """``ap_3d_r40_iou03`` -> ``3D AP R40 @ IoU 0.3``."""
    try:
        _, kind, rp, iou = metric.split("_")
        return f"{kind.upper()} AP {rp.upper()} @ IoU {iou[3]}.{iou[4:]}"
    except ValueError:
        return metric


def _color(condition: str, conditions: Sequence[str]) -> str:
    if condition in CONDITIONS:
        return CONDITIONS[condition].colour
    others = [c for c in conditions if c not in CONDITIONS]
    return _MORE_COLORS[others.index(condition) % len(_MORE_COLORS)]


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
    return 1.0 + _DODGE * (i - (k - 1) / 2)


def _ap_figure(stats: Mapping[str, Any], conds: Sequence[str], metric: str,
               folders: Mapping[tuple[str, float, int], str] | None = None) -> dict[str, Any]:
    """AP vs real-data fraction (paper Figure 4): per condition a ``mean`` trace (mean ± std
    error bars) and a ``trials`` trace (every trial's value; its hover names the run folder,
    ``folders``: (condition, fraction, trial) -> folder relative to the sweep)."""
    import plotly.graph_objects as go

    cells = {(c["condition"], float(c["fraction"])): c for c in stats.get("cells", [])}
    fractions = [float(f) for f in stats.get("fractions", [])]
    fig = go.Figure()
    for i, cond in enumerate(conds):
        color, label, dx = _color(cond, conds), condition_label(cond), _dodge(i, len(conds))
        xs, ys, es, info = [], [], [], []
        tx, ty, tinfo = [], [], []
        for f in fractions:
            cell = cells.get((cond, f))
            if cell is None:
                continue
            for t, v in zip(cell.get("trials", []), cell.get("values", []), strict=False):
                tx.append(100 * f * dx)
                ty.append(v)
                tinfo.append([_pct(f), t, (folders or {}).get((cond, f, int(t)), "—")])
            if cell.get("mean") is None:
                continue
            xs.append(100 * f * dx)
            ys.append(cell["mean"])
            es.append(cell.get("std") or 0.0)
            info.append([_pct(f), cell.get("std"), cell.get("n"), cell.get("n_failed"),
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
        template=_PLOTLY_TEMPLATE, height=440, margin={"l": 60, "r": 20, "t": 50, "b": 55},
        title={"text": f"{_metric_label(metric)} vs real data (mean ± std, every trial)"},
        xaxis=_fraction_axis(fractions), yaxis={"title": {"text": f"{_metric_label(metric)} [%]"},
                                                "rangemode": "tozero"},
        legend={"orientation": "h", "y": -0.2}, uirevision="keep")
    if not any(c.get("mean") is not None for c in stats.get("cells", [])):
        _empty_note(fig, "no finished run yet")
    return _fig_json(fig)


def _delta_figure(stats: Mapping[str, Any], conds: Sequence[str], metric: str,
                  ) -> dict[str, Any]:
    """Paired difference to the baseline per fraction: per non-baseline condition a ``delta``
    trace (mean difference with its Student-t interval), a ``delta-trials`` trace and an
    ``mde`` trace (the minimum detectable effect at 80 % power: a true Δ below it is more
    likely than not to be missed); one ``paper-delta`` trace (the paper's Table 1 Δ)."""
    import plotly.graph_objects as go

    level = f"{100 * (1 - float(stats.get('alpha', 0.05))):g} %"
    power = float((stats.get("power") or {}).get("power", 0.8))
    fractions = [float(f) for f in stats.get("fractions", [])]
    others = [c for c in conds if c != BASELINE]
    fig = go.Figure()
    fig.add_hline(y=0, line={"color": "#444", "width": 1, "dash": "dot"})
    for i, cond in enumerate(others):
        color, label, dx = _color(cond, conds), condition_label(cond), _dodge(i, len(others))
        comps = [c for c in stats.get("comparisons", []) if c["condition"] == cond]
        xs, ys, up, down, info = [], [], [], [], []
        tx, ty, tinfo = [], [], []
        mx, my, minfo = [], [], []
        for comp in comps:
            f = float(comp["fraction"])
            for t, d in zip(comp.get("trials", []), comp.get("differences", []), strict=False):
                tx.append(100 * f * dx)
                ty.append(d)
                tinfo.append([_pct(f), t])
            mde = _num(comp.get("mde"))
            if mde is not None:
                mx.append(100 * f)
                my.append(mde)
                minfo.append([_pct(f), comp.get("n_pairs"), comp.get("mde_alpha")])
            m = comp.get("mean_diff")
            if m is None:
                continue
            lo, hi = (comp.get("t_ci") or [None, None])[:2]
            b_lo, b_hi = (comp.get("bootstrap_ci") or [None, None])[:2]
            xs.append(100 * f * dx)
            ys.append(m)
            up.append(hi - m if hi is not None else 0.0)
            down.append(m - lo if lo is not None else 0.0)
            ci = "n/a" if lo is None else f"[{lo:+.2f}, {hi:+.2f}]"
            boot = "n/a" if b_lo is None else f"[{b_lo:+.2f}, {b_hi:+.2f}]"
            p = comp.get("p_holm")
            share = comp.get("p_improved")
            s_lo, s_hi = (comp.get("p_improved_ci") or [None, None])[:2]
            info.append([_pct(f), ci, boot, "n/a" if p is None else f"{p:.3g}",
                         f"{comp.get('k_improved', 0)}/{comp.get('n_pairs', 0)}",
                         comp.get("verdict", ""),
                         "n/a" if mde is None else f"{mde:.2f}",
                         "n/a" if share is None else
                         f"{100 * share:.0f} % [{100 * s_lo:.0f}, {100 * s_hi:.0f}]"])
        fig.add_trace(go.Scatter(
            x=xs, y=ys, mode="lines+markers", name=f"{label} − {condition_label(BASELINE)}",
            legendgroup=cond, line={"color": color, "width": 2.5},
            marker={"color": color, "size": 9},
            error_y={"type": "data", "symmetric": False, "array": up, "arrayminus": down,
                     "visible": True, "thickness": 1.5, "width": 5},
            customdata=info, meta={"role": "delta", "condition": cond},
            hovertemplate=(f"<b>{html.escape(label)}</b> %{{customdata[0]}}<br>"
                           f"Δ %{{y:+.2f}}, {level} t-interval %{{customdata[1]}}<br>"
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
        template=_PLOTLY_TEMPLATE, height=420, margin={"l": 60, "r": 20, "t": 50, "b": 55},
        title={"text": f"Δ {_metric_label(metric)} vs baseline, paired by trial "
                       f"(mean with its {level} t-interval; dashed: MDE at "
                       f"{100 * power:g} % power)"},
        xaxis=_fraction_axis(fractions), yaxis={"title": {"text": "Δ AP [points]"}},
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


def _curves_figure(runs: Sequence[Mapping[str, Any]], conds: Sequence[str]) -> dict[str, Any]:
    """Learning curves: per run a ``loss`` trace (training loss per epoch) and a ``val_ap``
    trace (validation AP), coloured by condition, against the optimiser step at the end of
    each epoch (``epoch x steps / epochs``): runs of different fractions have different
    epoch lengths, so steps put them on one axis."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    fig = make_subplots(rows=1, cols=2, horizontal_spacing=0.08,
                        subplot_titles=("training loss (mean per epoch)",
                                        "validation 3D AP R40 @ IoU 0.3 [%]"))
    shown: set[str] = set()
    n_curves = 0
    ordered = sorted(runs, key=lambda r: (conds.index(r["condition"]) if r.get("condition")
                                          in conds else len(conds), r.get("fraction") or 0,
                                          r.get("trial") or 0))
    for r in ordered:
        cond = str(r.get("condition"))
        epochs, loss = r.get("history_epoch") or [], r.get("history_loss") or []
        v_ep, v_ap = r.get("history_val_epoch") or [], r.get("history_val_ap") or []
        if not (epochs and loss) and not (v_ep and v_ap):
            continue
        color, label = _color(cond, conds), condition_label(cond)
        run = (f"{html.escape(label)} {_pct(float(r.get('fraction') or 0))}, "
               f"trial {r.get('trial')} (seed {r.get('seed')})")
        n_ep, n_steps = int(r.get("epochs") or 0), int(r.get("steps") or 0)
        per_epoch = n_steps / n_ep if n_ep > 0 and n_steps > 0 else 1.0
        epochs = [round(e * per_epoch) for e in epochs]
        v_ep = [round(e * per_epoch) for e in v_ep]
        for col, (x, y, role, fmt) in enumerate(((epochs, loss, "loss", ".4f"),
                                                 (v_ep, v_ap, "val_ap", ".2f")), start=1):
            if not (x and y):
                continue
            legend = cond not in shown  # one legend entry per condition
            shown.add(cond)
            fig.add_trace(go.Scatter(
                x=list(x), y=[_num(v) for v in y], mode="lines+markers" if len(x) < 3 else "lines",
                name=label, legendgroup=cond, showlegend=legend,
                line={"color": color, "width": 1.3}, marker={"size": 4}, opacity=0.75,
                meta={"role": role, "condition": cond, "run_key": r.get("run_key")},
                hovertemplate=f"{run}<br>step %{{x}}: %{{y:{fmt}}}<extra></extra>"),
                row=1, col=col)
            n_curves += 1
    for col in (1, 2):
        fig.update_xaxes(title_text="optimiser step", rangemode="tozero", row=1, col=col)
    fig.update_layout(template=_PLOTLY_TEMPLATE, height=380,
                      margin={"l": 60, "r": 20, "t": 50, "b": 55},
                      legend={"orientation": "h", "y": -0.25}, uirevision="keep")
    if not n_curves:
        _empty_note(fig, "no learning curve yet")
    return _fig_json(fig)


#: columns of the per-run table: (key, heading, type); the page formats and sorts by type
#: (``condition``: the registered name, shown by its label; ``run_folder`` is computed)
_RUN_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("condition", "condition", "condition"),
    ("fraction", "real data", "pct"),
    ("trial", "trial", "int"),
    ("seed", "seed", "int"),
    ("n_real_frames", "real frames", "int"),
    ("n_sim_frames", "sim frames", "int"),
    ("sim_real_ratio", "sim:real", "ratio"),
    *((m, _metric_label(m).replace(" @ IoU ", " @"), "ap") for m in AP_METRICS),
    ("epochs", "epochs", "int"),
    ("steps", "steps", "int"),
    ("wall_time_s", "wall time", "seconds"),
    ("device", "device", "text"),
    ("status", "status", "text"),
    ("error", "error", "text"),
    ("finished_at", "finished (UTC)", "text"),
    ("run_folder", "run folder", "text"),
    ("run_key", "run key", "key"),
    ("checkpoint", "checkpoint", "text"),
)


def run_folder(run: Mapping[str, Any], sweep_name: str) -> str | None:
    """The folder of a run relative to its sweep folder (POSIX separators), e.g.
    ``runs/<run_key>``.

    From the row's ``checkpoint`` (written relative to the sweep's parent folder,
    ``<sweep>/runs/<key>/last.pt``; a run found finished in the store keeps the checkpoint of
    the sweep that trained it, e.g. ``../other/runs/<key>``), else ``runs/<run_key>`` (where
    the sweep flow trains every run, a failed one included); None without either.
    """
    ckpt = str(run.get("checkpoint") or "").replace("\\", "/")
    if ckpt:
        parent = posixpath.dirname(ckpt)
        if posixpath.isabs(parent):
            return parent  # absolute: cannot be made relative without the sweep's own path
        return posixpath.relpath(parent, sweep_name or ".")
    key = run.get("run_key")
    return f"runs/{key}" if key else None


def _run_folders(runs: Sequence[Mapping[str, Any]], sweep_name: str,
                 ) -> dict[tuple[str, float, int], str]:
    """(condition, fraction, trial) -> run folder of the run whose value the statistics use (a
    finished one over a failed attempt of the same cell)."""
    out: dict[tuple[str, float, int], str] = {}
    for r in runs:
        if r.get("condition") is None or r.get("fraction") is None or r.get("trial") is None:
            continue
        key = (str(r["condition"]), float(r["fraction"]), int(r["trial"]))
        folder = run_folder(r, sweep_name)
        if folder and (key not in out or r.get("status") != "failed"):
            out[key] = folder
    return out


def _runs_table(runs: Sequence[Mapping[str, Any]], metric: str,
                sweep_name: str) -> dict[str, Any]:
    cols = list(_RUN_COLUMNS)
    ap_start = next(i for i, c in enumerate(cols) if c[2] == "ap")
    head = next(i for i, c in enumerate(cols) if c[0] == metric)
    cols.insert(ap_start, cols.pop(head))  # the sweep's metric first among the APs
    rows = [[run_folder(r, sweep_name) if k == "run_folder" else _clean(r.get(k))
             for k, _, _ in cols] for r in runs]
    keys = [c[0] for c in cols]
    return {"columns": [{"key": k, "label": label, "type": t} for k, label, t in cols],
            "rows": rows, "status_column": keys.index("status"),
            "metric_column": keys.index(metric),
            "group_columns": [keys.index(k) for k in ("condition", "fraction", "trial")]}


def _banner(sweep: Mapping[str, Any] | None) -> dict[str, str]:
    if sweep is None:
        return {"kind": "unknown", "text": "Real domain unknown: sweep.json is missing, so this "
                "page cannot say whether the 'real' data is measured radar or a proxy. Treat "
                "the results as unverified."}
    real = (sweep.get("datasets") or {}).get("real") or {}
    domain = str(sweep.get("real_domain") or real.get("domain") or UNDECLARED)
    kind = domain_kind(domain, sweep.get("real_is_proxy"))
    if kind == "proxy":
        return {"kind": "proxy", "text": f"PROXY real domain — {domain}. The 'real' radar of "
                "this sweep is a stand-in for measured radar (the reference radar simulation). "
                "Its results are not claims about measured radar."}
    if kind == "undeclared":
        return {"kind": "undeclared", "text": "Real domain undeclared: the real dataset's "
                "dataset.json declares no domain, so this page cannot say whether it is "
                "measured radar. Its results are not claims about measured radar until it is "
                "declared."}
    if kind == "declared":
        return {"kind": "declared", "text": f"Real domain: {domain} (as its dataset.json "
                "declares) — not measured radar. Its results are not claims about measured "
                "radar."}
    return {"kind": "measured", "text": f"Real domain: {domain} (measured radar)."}


def _progress(data: SweepData, conds: Sequence[str]) -> dict[str, Any]:
    sweep, prog = data.sweep or {}, data.progress or {}
    counts = {s: sum(r.get("status") == s for r in data.runs) for s in ("ok", "skipped",
                                                                        "failed")}
    planned = None
    if sweep.get("n_runs") is not None:
        planned = int(sweep["n_runs"])
    elif sweep.get("fractions") and sweep.get("trials"):
        planned = len(conds) * len(sweep["fractions"]) * int(sweep["trials"])
    total = prog.get("total_runs") if prog.get("total_runs") is not None else planned
    finished = len(data.runs)
    total = max(int(total), finished) if total is not None else finished
    running = prog.get("running") or []
    state = ("no run planned" if total == 0 else "complete" if finished >= total
             else "not started" if finished == 0 else "running")
    return {"finished": finished, "total": total, "ok": counts["ok"],
            "skipped": counts["skipped"], "failed": counts["failed"],
            "running": [r if isinstance(r, str) else json.dumps(_clean(r)) for r in running],
            "updated_at": prog.get("updated_at"), "state": state}


#: summary columns shown left-aligned (text); every other column is a number
_TEXT_SUMMARY_COLUMNS = ("condition", "real data", "verdict")


def _summary_table(stats: Mapping[str, Any]) -> dict[str, Any]:
    """Table 1 (paper) as strings: one row per (non-baseline condition, fraction), with the
    MDE beside Δ, P(improved) beside k/n (:func:`~.report.results_table_rows`); ``numeric``
    flags the right-aligned columns; ``sentences`` says what the sweep could and could not
    have detected (:func:`~.report.detectability_sentences`)."""
    rows = results_table_rows(stats)
    sentences = detectability_sentences(stats)
    if not rows:
        return {"columns": [], "rows": [], "numeric": [], "sentences": sentences}
    cols = list(rows[0])
    return {"columns": cols, "rows": [[condition_label(r[c]) if c == "condition" else r[c]
                                       for c in cols] for r in rows],
            "numeric": [c not in _TEXT_SUMMARY_COLUMNS for c in cols],
            "sentences": sentences}


def _fmt(v: Any, spec: str = ",.1f") -> str:
    """A number for a fact table: integers with thousands separators, floats with ``spec``."""
    if isinstance(v, int) and not isinstance(v, bool):
        return f"{v:,}"
    f = _num(v)
    if f is None:
        return "—" if v is None else str(v)
    return format(f, spec)


def _generation(data: SweepData) -> dict[str, Any]:
    sweep = data.sweep or {}
    datasets = []
    for role, d in (sweep.get("datasets") or {}).items():
        if not isinstance(d, Mapping):
            continue
        splits = d.get("splits") or {}
        datasets.append({"role": str(role), "domain": str(d.get("domain", "")),
                         "frames": d.get("n_frames"),
                         "splits": ", ".join(f"{k} {v}" for k, v in splits.items()),
                         "path": str(d.get("path", "")), "key": str(d.get("key", ""))})
    gen = None
    if data.generation is not None:
        gen = []
        for d in data.generation.get("datasets", []):
            if not isinstance(d, Mapping):
                continue
            gen.append({"name": str(d.get("name", "")), "role": str(d.get("role", "")),
                        "scenes_ok": d.get("scenes_ok"), "scenes_failed": d.get("scenes_failed"),
                        "scenes_skipped": d.get("scenes_skipped"), "frames": d.get("frames"),
                        "points_per_frame": _fmt(d.get("points_per_frame_mean")),
                        "labels_per_frame": _fmt(d.get("labels_per_frame_mean"), ".2f")})
    return _clean({"datasets": datasets, "generation": gen})


def _share_cell(v: Any) -> str:
    f = _num(v)
    return "—" if f is None else f"{100 * f:.1f} %"


def _gap_artefact_rows(art: Any) -> list[list[str]]:
    """Rows [label, sim, real] of ``gap.json["artefacts"]`` (sim2radar.evaluate.gap
    .artefacts_dict); "—" cells for a report without them (written before they existed)."""
    art = art if isinstance(art, Mapping) else {}
    st = art.get("settings") if isinstance(art.get("settings"), Mapping) else {}
    sides = [a if isinstance(a, Mapping) else {} for a in (art.get("sim"), art.get("real"))]
    far, margin = _num(st.get("far_range_m")), _num(st.get("below_floor_margin_m"))

    def sidelobe(a: Mapping) -> str:
        share, ctl = _num(a.get("sidelobe_share")), _num(a.get("sidelobe_control_share"))
        if share is None and ctl is None:
            return "—"
        return f"{_share_cell(share)} / {_share_cell(ctl)}"

    def doppler(a: Mapping) -> str:
        d = a.get("doppler")
        if isinstance(d, Mapping):
            med = _num(d.get("abs_median_mps"))
            return (f"{_share_cell(d.get('moving_share'))} (median |v| "
                    f"{'—' if med is None else f'{med:.2f}'} m/s)")
        return str(a.get("doppler_note") or "—")

    def below(a: Mapping) -> str:
        if a.get("below_floor_share") is None:
            return str(a.get("below_floor_note") or "—")
        return _share_cell(a.get("below_floor_share"))

    return [
        ["sidelobe-bin share / control", *(sidelobe(a) for a in sides)],
        ["Doppler: moving share", *(doppler(a) for a in sides)],
        [f"range > {'8' if far is None else f'{far:g}'} m",
         *(_share_cell(a.get("beyond_range_share")) for a in sides)],
        [f"> {'0.1' if margin is None else f'{margin:g}'} m below the floor",
         *(below(a) for a in sides)],
    ]


def _gap(data: SweepData) -> dict[str, Any] | None:
    gap = data.gap
    if gap is None:
        return None
    sim, real = gap.get("sim") or {}, gap.get("real") or {}
    fov = (gap.get("azimuth") or {}).get("effective_fov_deg") or {}
    rows = [["frames analysed", _fmt(sim.get("frames")), _fmt(real.get("frames"))],
            ["points per frame (mean)", _fmt(sim.get("points_per_frame_mean")),
             _fmt(real.get("points_per_frame_mean"))],
            ["points per frame (median)", _fmt(sim.get("points_per_frame_median")),
             _fmt(real.get("points_per_frame_median"))],
            ["effective azimuth FOV [°]", _fmt(fov.get("sim")), _fmt(fov.get("real"))],
            ["domain (dataset.json)", str(sim.get("domain") or "—"),
             str(real.get("domain") or "—")],
            *_gap_artefact_rows(gap.get("artefacts")),
            ["dataset folder", str(sim.get("root", "—")), str(real.get("root", "—"))]]
    ratio = _num(gap.get("points_ratio"))
    ch = gap.get("chamfer")
    facts = [["points ratio sim / real", "—" if ratio is None else f"{100 * ratio:.1f} %"],
             ["Chamfer distance (shared frames)",
              "no frame id in both datasets" if not isinstance(ch, Mapping) else
              f"{_fmt(ch.get('mean_m'), '.3f')} m over {ch.get('pairs')} frame(s)"],
             ["intensity matching fitted on",
              str((gap.get("intensity") or {}).get("fitted_on", "—"))],
             ["overlay frame", str(gap.get("overlay_frame") or "—")]]
    definition = (gap.get("azimuth") or {}).get("definition")
    if definition:
        facts.append(["effective FOV", str(definition)])
    art = gap.get("artefacts")
    defs = (art.get("definitions") if isinstance(art, Mapping) else None) or {}
    if isinstance(defs, Mapping):
        for key, label in (("sidelobe", "sidelobe share"), ("doppler", "Doppler"),
                           ("beyond_range", "range coverage"), ("below_floor", "below floor")):
            if defs.get(key):
                facts.append([label, str(defs[key])])
    figures = [{"name": name, "uri": uri} for name, uri in data.gap_images.items()]
    return _clean({"rows": rows, "facts": facts, "figures": figures})


def _provenance(sweep: Mapping[str, Any] | None) -> dict[str, Any] | None:
    if sweep is None:
        return None
    prov = sweep.get("provenance") or {}
    code = prov.get("code")
    git = prov.get("git")
    return _clean({
        "created_at": sweep.get("created_at"),
        "settings_fixed_at": sweep.get("settings_fixed_at"),
        "settings_digest": sweep.get("settings_digest"),
        "versions": prov.get("versions") or {},
        "code": code if isinstance(code, Mapping) else ({"code": code} if code else {}),
        "git": git if isinstance(git, str) else (json.dumps(_clean(git)) if git else None),
        "configs": {k: json.dumps(_clean(v), indent=1) for k, v in
                    (prov.get("configs") or {}).items()},
        "profile": json.dumps(_clean(sweep.get("profile") or {}), indent=1),
        "intensity_match": json.dumps(_clean(sweep.get("intensity_match")), indent=1)
        if sweep.get("intensity_match") else None,
    })


def dashboard_data(sweep: SweepData) -> dict[str, Any]:
    """Everything the page shows, as one JSON-able dict (what ``/data.json`` serves).

    Parameters
    ----------
    sweep : :func:`load_sweep`'s result.

    Returns
    -------
    dict with keys ``name``, ``folder``, ``metric``, ``metric_label``, ``created_at``,
    ``profile``, ``banner`` (``{"kind": "proxy" | "measured" | "undeclared" | "declared" |
    "unknown", "text"}``),
    ``progress`` (``finished``, ``total``, ``ok``, ``skipped``, ``failed``, ``running``,
    ``updated_at``, ``state``), ``conditions`` (``[{"name", "label", "color"}]``),
    ``fractions``, ``figures`` (Plotly ``{"data", "layout"}`` of ``ap``, ``delta``, ``curves``;
    trace ``meta.role`` ``mean``/``trials``, ``delta``/``delta-trials``, ``loss``/``val_ap``),
    ``summary`` (Table 1: ``columns``, ``rows`` of strings with the MDE and P(improved) per
    cell, ``numeric``, ``sentences``: what the sweep could and could not detect), ``notes``,
    ``stats_source``, ``runs`` (``columns`` ``[{"key", "label", "type"}]``, ``rows``: one
    list per run with its ``run_folder`` relative to the sweep; ``status_column``,
    ``metric_column``, ``group_columns``: indices of condition, fraction, trial),
    ``datasets``, ``generation``, ``gap`` (None without ``gap/gap.json``), ``provenance``
    (None without ``sweep.json``), ``warnings``, ``error`` (None; set by the live server when
    the folder cannot be read).
    No NaN anywhere (``json.dumps(..., allow_nan=False)`` works).
    """
    sweep_doc = sweep.sweep or {}
    stats = sweep.stats or {"cells": [], "comparisons": [], "conditions": [], "fractions": [],
                            "notes": [], "alpha": 0.05, "metric": DEFAULT_METRIC}
    conds = list(dict.fromkeys([*stats.get("conditions", []),
                                *_conditions(sweep.sweep, sweep.runs)]))
    if BASELINE in conds:
        conds = [BASELINE, *(c for c in conds if c != BASELINE)]
    metric = str(stats.get("metric") or sweep_doc.get("metric") or DEFAULT_METRIC)
    profile = sweep_doc.get("profile") or {}
    gen = _generation(sweep)
    name = str(sweep_doc.get("name") or sweep.folder.name)
    folders = _run_folders(sweep.runs, sweep.folder.name)
    data = {
        "name": name,
        "folder": str(sweep.folder),
        "metric": metric,
        "metric_label": _metric_label(metric),
        "created_at": sweep_doc.get("created_at"),
        "profile": profile.get("name") if isinstance(profile, Mapping) else None,
        "banner": _banner(sweep.sweep),
        "progress": _progress(sweep, conds),
        "conditions": [{"name": c, "label": condition_label(c), "color": _color(c, conds)}
                       for c in conds],
        "fractions": [float(f) for f in stats.get("fractions", [])],
        "figures": {"ap": _ap_figure(stats, conds, metric, folders),
                    "delta": _delta_figure(stats, conds, metric),
                    "curves": _curves_figure(sweep.runs, conds)},
        "summary": _summary_table(stats),
        "notes": [str(n) for n in stats.get("notes", [])],
        "stats_source": sweep.stats_source,
        "runs": _runs_table(sweep.runs, metric, sweep.folder.name),
        "datasets": gen["datasets"],
        "generation": gen["generation"],
        "gap": _gap(sweep),
        "provenance": _provenance(sweep.sweep),
        "warnings": list(sweep.warnings),
        "error": None,
    }
    return _clean(data)


def _error_data(folder: str | os.PathLike, message: str) -> dict[str, Any]:
    """The page's data for a folder that cannot be read (the live server's first page)."""
    data = dashboard_data(SweepData(folder=Path(folder), runs=[]))
    data["error"] = message
    return data


# ---------------------------------------------------------------------------------------------
# The page (pure)
# ---------------------------------------------------------------------------------------------
#: the page loads nothing: inline scripts and styles, images as data: URIs, and (live) its own
#: data.json; fonts, frames and every other fetch are refused by the browser
_CSP = ("default-src 'none'; script-src 'unsafe-inline'; "
        "style-src 'unsafe-inline'; img-src data: blob:; font-src data:; "
        "connect-src {connect}; base-uri 'none'; form-action 'none'")

_CSS = """
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#222;
 background:#fafafa}
header,main{max-width:1280px;margin:0 auto;padding:0 20px}
header{padding-top:16px}
h1{font-size:22px;margin:4px 0}h2{font-size:17px;margin:26px 0 8px;border-bottom:1px solid #ddd;
 padding-bottom:4px}
.sub{color:#555}.muted{color:#777}
#banner{margin:12px 0;padding:12px 16px;border-radius:6px;font-weight:600}
#banner.proxy{background:#fff3cd;border:2px solid #e0a800;color:#5c4400;font-size:15px}
#banner.unknown,#banner.undeclared{background:#fde2e1;border:2px solid #d9534f;color:#6b1a17}
#banner.declared{background:#fff3cd;border:2px solid #e0a800;color:#5c4400}
#banner.measured{background:#e7f4e8;border:1px solid #7bbf7f;color:#1e4620;font-weight:500}
#error{display:none;margin:8px 0;padding:10px 14px;background:#fde2e1;border:1px solid #d9534f;
 border-radius:6px;color:#6b1a17}
#live-status{font-size:12px;color:#666}
.card{background:#fff;border:1px solid #e3e3e3;border-radius:6px;padding:10px 14px;margin:8px 0}
.plot{min-height:380px}
table{border-collapse:collapse;font-size:12.5px;background:#fff}
th,td{border:1px solid #e1e1e1;padding:3px 7px;text-align:left;vertical-align:top}
#runs-table td{white-space:nowrap}
th{background:#f1f3f5;position:sticky;top:0}
td.num{text-align:right;font-variant-numeric:tabular-nums}
.scroll{overflow:auto;max-height:560px;border:1px solid #e3e3e3}
#runs-table th{cursor:pointer;user-select:none;white-space:nowrap}
#runs-table th[aria-sort=ascending]::after{content:" \\25B2"}
#runs-table th[aria-sort=descending]::after{content:" \\25BC"}
tr.failed td{background:#fdecea}
#runs-table td.err{min-width:240px;max-width:420px;white-space:pre-wrap;word-break:break-word;font-family:monospace;
 font-size:11.5px}
progress{width:320px;height:14px;vertical-align:middle}
.counts span{margin-right:14px}
.gap-figs{display:flex;flex-wrap:wrap;gap:12px}
.gap-figs figure{margin:0;background:#fff;border:1px solid #e3e3e3;padding:6px;max-width:600px}
.gap-figs img{max-width:100%;height:auto;display:block}
pre{max-height:360px;overflow:auto;background:#f6f8fa;padding:8px;font-size:12px}
details{margin:6px 0}
ul.notes li{margin:3px 0}
#power-summary{margin:8px 0;padding:8px 14px;background:#eef4fb;border-left:4px solid #1f77b4}
#power-summary p{margin:4px 0}
#runs-controls{display:flex;flex-wrap:wrap;gap:12px;align-items:center;margin:6px 0}
#runs-controls label{font-size:13px}
tr.group td{background:#eef1f4;font-weight:600;white-space:normal}
"""

# The page's script: render(data) fills every section from the JSON document; the live page
# polls data.json and calls render again when it changed. Table sort state survives re-renders.
_JS = r"""
(function () {
"use strict";
const CONFIG = {responsive: true, displaylogo: false};
const state = {data: null, text: null, sortCol: null, sortDir: 1, renders: 0,
  filter: {}, groupBy: "", shown: []};
window.dashboard = state;
const $ = (id) => document.getElementById(id);
function esc(v) {
  return String(v).replace(/[&<>"']/g, (c) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;",
    '"': "&quot;", "'": "&#39;"}[c]));
}
function fmt(v, type) {
  if (v === null || v === undefined || v === "") return type === "text" ? "" : "—";
  switch (type) {
    case "pct": return (100 * v).toLocaleString("en", {maximumFractionDigits: 2}) + " %";
    case "ap": return Number(v).toFixed(2);
    case "ratio": return Number(v).toFixed(1) + ":1";
    case "int": return String(v);
    case "seconds": return v >= 3600 ? (v / 3600).toFixed(2) + " h" :
      v >= 60 ? (v / 60).toFixed(1) + " min" : Number(v).toFixed(1) + " s";
    case "key": return String(v).slice(0, 12);
    case "condition": return label(v);
    default: return String(v);
  }
}
function label(name) {
  const c = (state.data.conditions || []).find((x) => x.name === name);
  return c ? c.label : String(name);
}
function table(columns, rows, numeric) {  // numeric: (column index) -> right-align
  const head = "<tr>" + columns.map((c) => "<th>" + esc(c) + "</th>").join("") + "</tr>";
  const body = rows.map((r) => "<tr>" + r.map((v, i) =>
    "<td" + (numeric && numeric(i) ? " class=num" : "") + ">" + esc(v === null ||
      v === undefined ? "—" : v) + "</td>").join("") + "</tr>").join("");
  return "<table><thead>" + head + "</thead><tbody>" + body + "</tbody></table>";
}
function plot(id, fig) {
  if (!fig) { $(id).innerHTML = ""; return; }
  Plotly.react($(id), fig.data, fig.layout, CONFIG);
}
function compare(a, b, type) {
  const na = a === null || a === undefined || a === "", nb = b === null || b === undefined ||
    b === "";
  if (na || nb) return na && nb ? 0 : na ? 1 : -1;   // empty cells last, either direction
  if (type === "text" || type === "key" || type === "condition")
    return state.sortDir * String(a).localeCompare(String(b));
  return state.sortDir * (a - b);
}
// the rows the filters let through, sorted, in group order when grouped
function visibleRuns() {
  const runs = state.data.runs, cols = runs.columns;
  let rows = runs.rows.filter((r) => runs.group_columns.every((i) => {
    const want = state.filter[cols[i].key];
    return want === undefined || want === "" || String(r[i]) === want;
  }));
  if (state.sortCol !== null && state.sortCol < cols.length) {
    const i = state.sortCol, t = cols[i].type;
    rows = rows.slice().sort((a, b) => compare(a[i], b[i], t));
  }
  const g = cols.findIndex((c) => c.key === state.groupBy);
  if (g >= 0) {  // stable: keeps the sort order within each group
    const keys = [...new Set(rows.map((r) => String(r[g])))].sort((a, b) =>
      cols[g].type === "condition" || cols[g].type === "text" ? a.localeCompare(b) : a - b);
    rows = keys.flatMap((k) => rows.filter((r) => String(r[g]) === k));
  }
  return {rows: rows, group: g};
}
function renderControls() {
  const runs = state.data.runs, cols = runs.columns;
  let out = "";
  for (const i of runs.group_columns) {
    const c = cols[i], cur = state.filter[c.key] || "";
    const values = [...new Set(runs.rows.map((r) => r[i]).filter((v) => v !== null))]
      .sort((a, b) => (typeof a === "number" ? a - b : String(a).localeCompare(String(b))));
    out += "<label>" + esc(c.label) + " <select id='filter-" + esc(c.key) + "' data-key='" +
      esc(c.key) + "'><option value=''>all</option>" + values.map((v) => "<option value='" +
      esc(v) + "'" + (String(v) === cur ? " selected" : "") + ">" + esc(fmt(v, c.type)) +
      "</option>").join("") + "</select></label>";
  }
  out += "<label>group by <select id='group-by'><option value=''>none</option>" +
    runs.group_columns.map((i) => "<option value='" + esc(cols[i].key) + "'" +
    (cols[i].key === state.groupBy ? " selected" : "") + ">" + esc(cols[i].label) +
    "</option>").join("") + "</select></label>" +
    "<button type=button id='download-csv'>download CSV</button>" +
    "<button type=button id='download-json'>download JSON</button>" +
    "<span class=muted id='runs-shown'></span>";
  $("runs-controls").innerHTML = out;
}
function renderRuns() {
  const runs = state.data.runs, cols = runs.columns;
  const head = cols.map((c, i) => "<th data-col=" + i + " title='sort by " + esc(c.label) +
    "' aria-sort=" + (state.sortCol === i ? (state.sortDir > 0 ? "ascending" : "descending") :
    "none") + ">" + esc(c.label) + "</th>").join("");
  const vis = visibleRuns(), rows = vis.rows;
  state.shown = rows;
  const statusCol = runs.status_column, metricCol = runs.metric_column;
  let body = "", last = null;
  for (const r of rows) {
    if (vis.group >= 0 && String(r[vis.group]) !== last) {
      last = String(r[vis.group]);
      const members = rows.filter((x) => String(x[vis.group]) === last);
      const vals = members.map((x) => x[metricCol]).filter((v) => v !== null);
      const mean = vals.length ? vals.reduce((a, b) => a + b, 0) / vals.length : null;
      body += "<tr class=group><td colspan=" + cols.length + ">" +
        esc(cols[vis.group].label) + " " + esc(fmt(r[vis.group], cols[vis.group].type)) +
        " · " + members.length + " run(s) · mean " + esc(cols[metricCol].label) + " " +
        (mean === null ? "—" : mean.toFixed(2)) + "</td></tr>";
    }
    body += "<tr class='run" + (r[statusCol] === "failed" ? " failed" : "") + "'>" +
      r.map((v, i) => {
        const t = cols[i].type, title = t === "key" && v ? " title='" + esc(v) + "'" : "";
        const cls = cols[i].key === "error" ? " class=err" : (t !== "text" && t !== "key" &&
          t !== "condition" ? " class=num" : "");
        return "<td" + cls + title + ">" + esc(fmt(v, t)) + "</td>";
      }).join("") + "</tr>";
  }
  $("runs-table").innerHTML = "<thead><tr>" + head + "</tr></thead><tbody>" + body +
    "</tbody>";
  $("runs-empty").style.display = rows.length ? "none" : "block";
  const shown = $("runs-shown");
  if (shown) shown.textContent = rows.length + " of " + runs.rows.length + " runs shown";
}
// downloads of the rows shown (raw values, every column), built here: the page fetches nothing
function csvCell(v, type) {
  if (v === null || v === undefined) return "";
  let s = typeof v === "object" ? JSON.stringify(v) : String(v);
  if (type === "text" && /^[=+\-@\t\r]/.test(s)) s = "'" + s;  // no formulas in spreadsheets
  return /[",\r\n]/.test(s) ? '"' + s.replace(/"/g, '""') + '"' : s;
}
function runsCsv(rows) {
  const cols = state.data.runs.columns;
  return [cols.map((c) => csvCell(c.key, "key")).join(",")].concat(rows.map((r) =>
    r.map((v, i) => csvCell(v, cols[i].type)).join(","))).join("\r\n") + "\r\n";
}
function runsJson(rows) {
  const cols = state.data.runs.columns;
  return JSON.stringify(rows.map((r) => Object.fromEntries(cols.map((c, i) => [c.key, r[i]]))),
    null, 1);
}
function download(text, type, ext) {
  const url = URL.createObjectURL(new Blob([text], {type: type}));
  const a = document.createElement("a");
  a.href = url; a.download = "sweep-" + state.data.name + "-runs." + ext;
  document.body.appendChild(a); a.click(); a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 1000);
}
window.dashboardExport = {csv: () => runsCsv(state.shown), json: () => runsJson(state.shown)};
function renderProgress(p) {
  $("run-count").textContent = p.finished;
  $("run-total").textContent = p.total;
  $("run-state").textContent = p.state;
  const bar = $("run-progress");
  bar.max = Math.max(p.total, 1); bar.value = p.finished;
  $("run-counts").innerHTML = "<span>computed: <b id=count-ok>" + p.ok + "</b></span>" +
    "<span>cached: <b id=count-skipped>" + p.skipped + "</b></span>" +
    "<span>failed: <b id=count-failed" + (p.failed ? " style='color:#c0392b'" : "") + ">" +
    p.failed + "</b></span>" + (p.updated_at ? "<span class=muted>progress.json " +
    esc(p.updated_at) + "</span>" : "");
  $("run-running").innerHTML = p.running.length ? "running: " + p.running.map(esc).join(", ")
    : "";
}
function renderDatasets(d) {
  let out = "";
  if (d.datasets.length) {
    out += "<h3>Datasets of the sweep</h3>" + table(["role", "domain", "frames", "splits",
      "path", "content key"], d.datasets.map((x) => [x.role, x.domain, x.frames, x.splits,
      x.path, x.key]), (i) => i === 2);
  }
  if (d.generation) {
    out += "<h3>Dataset generation</h3>" + table(["dataset", "role", "scenes ok",
      "scenes failed", "scenes skipped", "frames", "points / frame", "labels / frame"],
      d.generation.map((x) => [x.name, x.role, x.scenes_ok, x.scenes_failed, x.scenes_skipped,
      x.frames, x.points_per_frame, x.labels_per_frame]), (i) => i >= 2);
  } else {
    out += "<p class=muted>No generation.json in the sweep folder: dataset generation status " +
      "not recorded.</p>";
  }
  $("datasets").innerHTML = out;
}
function renderGap(g) {
  if (!g) {
    $("gap").innerHTML = "<p class=muted>No sim–real gap report in this sweep folder " +
      "(gap/gap.json): <code>sim2radar gap SIM REAL --out &lt;sweep&gt;/gap</code> writes one.</p>";
    return;
  }
  let out = table(["", "sim", "real"], g.rows, (i) => i > 0) + "<br>" +
    table(["", ""], g.facts, null);
  out += "<div class=gap-figs>" + g.figures.map((f) => "<figure><img alt='" + esc(f.name) +
    "' src='" + esc(f.uri) + "'><figcaption>" + esc(f.name) + "</figcaption></figure>").join("")
    + "</div>";
  $("gap").innerHTML = out;
}
function renderProvenance(p) {
  if (!p) {
    $("provenance").innerHTML = "<p class=muted>sweep.json not found: no provenance.</p>";
    return;
  }
  let out = "<p>created " + esc(p.created_at || "—") + (p.git ? " · git " + esc(p.git) : "") +
    "</p>";
  if (p.settings_digest) out += "<p>settings (digest " + esc(p.settings_digest) +
    ") fixed at " + esc(p.settings_fixed_at || "—") +
    ", before any run; a rerun with changed settings is refused</p>";
  const code = Object.entries(p.code || {});
  if (code.length) out += "<h3>Code</h3>" + table(["", ""], code, null);
  out += "<h3>Package versions</h3>" + table(["package", "version"],
    Object.entries(p.versions || {}), null);
  for (const [name, text] of Object.entries(p.configs || {})) {
    out += "<details><summary>detector config: " + esc(name) + "</summary><pre>" + esc(text) +
      "</pre></details>";
  }
  out += "<details><summary>experiment profile</summary><pre>" + esc(p.profile) +
    "</pre></details>";
  if (p.intensity_match) out += "<details><summary>intensity matching</summary><pre>" +
    esc(p.intensity_match) + "</pre></details>";
  $("provenance").innerHTML = out;
}
function render(d) {
  state.data = d;
  document.title = "sim2radar sweep " + d.name;
  $("title").textContent = "Sweep " + d.name;
  $("subtitle").textContent = [d.profile ? "profile " + d.profile : null, "metric " +
    d.metric_label, d.created_at ? "created " + d.created_at : null, d.folder]
    .filter(Boolean).join(" · ");
  const b = $("banner");
  b.className = d.banner.kind; b.textContent = d.banner.text;
  const err = $("error");
  err.style.display = d.error ? "block" : "none"; err.textContent = d.error || "";
  renderProgress(d.progress);
  plot("plot-ap", d.figures.ap);
  plot("plot-delta", d.figures.delta);
  plot("plot-curves", d.figures.curves);
  $("summary").innerHTML = d.summary.rows.length ? table(d.summary.columns, d.summary.rows,
    (i) => (d.summary.numeric || [])[i]) : "<p class=muted>No comparison yet.</p>";
  const sentences = d.summary.sentences || [];
  $("power-summary").innerHTML = sentences.map((x) => "<p>" + esc(x) + "</p>").join("");
  $("power-summary").style.display = sentences.length ? "block" : "none";
  $("notes").innerHTML = d.notes.map((n) => "<li>" + esc(n) + "</li>").join("");
  $("stats-source").textContent = "statistics: " + d.stats_source;
  renderControls();
  renderRuns();
  renderDatasets(d);
  renderGap(d.gap);
  renderProvenance(d.provenance);
  $("warnings").innerHTML = d.warnings.map((w) => "<li>" + esc(w) + "</li>").join("");
  $("warnings-section").style.display = d.warnings.length ? "block" : "none";
  state.renders += 1;
}
$("runs-controls").addEventListener("change", (e) => {
  const el = e.target;
  if (el.id === "group-by") state.groupBy = el.value;
  else if (el.dataset && el.dataset.key) state.filter[el.dataset.key] = el.value;
  renderRuns();
});
$("runs-controls").addEventListener("click", (e) => {
  if (e.target.id === "download-csv") download(runsCsv(state.shown), "text/csv", "csv");
  if (e.target.id === "download-json") download(runsJson(state.shown), "application/json",
    "json");
});
$("runs-table").addEventListener("click", (e) => {
  const th = e.target.closest("th[data-col]");
  if (!th) return;
  const i = Number(th.dataset.col);
  state.sortDir = state.sortCol === i ? -state.sortDir : 1;
  state.sortCol = i;
  renderRuns();
});
const initial = $("dashboard-data").textContent;
state.text = initial;
render(JSON.parse(initial));
const live = JSON.parse($("dashboard-live").textContent);
if (live.poll_ms > 0) {
  const status = $("live-status");
  async function poll() {
    try {
      const r = await fetch("data.json", {cache: "no-store"});
      const text = await r.text();
      if (!r.ok) {
        let msg = text;
        try { msg = JSON.parse(text).error; } catch (e) { /* plain text */ }
        $("error").style.display = "block"; $("error").textContent = msg;
      } else {
        if (text !== state.text) { state.text = text; render(JSON.parse(text)); }
        else { $("error").style.display = state.data.error ? "block" : "none"; }
        status.textContent = "live · checked " + new Date().toLocaleTimeString() +
          " · every " + live.poll_ms / 1000 + " s";
      }
    } catch (e) {
      status.textContent = "live · server unreachable at " + new Date().toLocaleTimeString() +
        "; retrying";
    }
    setTimeout(poll, live.poll_ms);
  }
  setTimeout(poll, live.poll_ms);
}
})();
"""

_BODY = """<header>
<h1 id="title">{title}</h1>
<div class="sub" id="subtitle"></div>
<div id="live-status">{live_line}</div>
<div id="banner" class="{banner_kind}" role="alert">{banner_text}</div>
<div id="error" role="alert"></div>
</header>
<main>
<section id="progress-section"><h2>Progress</h2>
<div class="card"><b id="run-count">0</b> of <b id="run-total">0</b> runs finished
(<span id="run-state"></span>) <progress id="run-progress" value="0" max="1"></progress>
<div class="counts" id="run-counts"></div><div class="muted" id="run-running"></div></div>
</section>
<section><h2>AP vs real-data fraction</h2>
<div class="card"><div id="plot-ap" class="plot"></div></div></section>
<section><h2>Difference to the baseline</h2>
<div id="power-summary" role="note"></div>
<div class="card"><div id="plot-delta" class="plot"></div></div>
<div class="scroll" id="summary"></div>
<p class="muted" id="stats-source"></p><ul class="notes" id="notes"></ul></section>
<section><h2>Learning curves</h2>
<div class="card"><div id="plot-curves" class="plot"></div></div></section>
<section><h2>Runs</h2><p class="muted">Click a column heading to sort; filter and group by
condition, fraction and trial; the downloads hold the runs shown. Each run's folder is relative
to the sweep folder.</p>
<div id="runs-controls"></div>
<div class="scroll"><table id="runs-table"></table></div>
<p class="muted" id="runs-empty">No run has finished yet.</p></section>
<section><h2>Datasets</h2><div id="datasets"></div></section>
<section><h2>Sim–real gap</h2><div id="gap"></div></section>
<section><h2>Provenance</h2><div id="provenance"></div></section>
<section id="warnings-section"><h2>Warnings</h2><ul id="warnings"></ul></section>
<p class="muted">{footer}</p>
</main>"""


def _script_json(doc: Any) -> str:
    """JSON for an inline ``<script type="application/json">``: ``<``, ``>``, ``&`` escaped so
    no text in the data can close the element."""
    text = json.dumps(doc, allow_nan=False, separators=(",", ":"), ensure_ascii=False)
    return (text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
            .replace("\u2028", "\\u2028").replace("\u2029", "\\u2029"))


def _plotly_js() -> str:
    from plotly.offline import get_plotlyjs

    js = get_plotlyjs()
    if "</script" in js.lower():  # plotly's own to_html relies on the same property
        raise RuntimeError("the Plotly bundle contains '</script': it cannot be inlined")
    return js


def render_html(data: Mapping[str, Any], *, live: bool = False, poll_s: float = POLL_S) -> str:
    """The dashboard page: one self-contained HTML document.

    Parameters
    ----------
    data : :func:`dashboard_data`'s dict.
    live : poll ``data.json`` (relative to the page) every ``poll_s`` seconds and re-render
        when it changed; for the page :func:`serve_dashboard` serves.
    poll_s : seconds between polls [s] (live only).

    Returns
    -------
    str — HTML with Plotly's bundle, the page's script and the data inline; a
    Content-Security-Policy lets it load nothing else (the live page: its own origin's
    ``data.json``).
    """
    if live and not poll_s > 0:
        raise ValueError(f"poll_s must be > 0, got {poll_s}")
    banner = data.get("banner") or {"kind": "unknown", "text": ""}
    csp = _CSP.format(connect="'self'" if live else "'none'")
    live_line = ("live · polling for new runs" if live
                 else "static snapshot")
    footer = (f"Live view of {data.get('folder', '')}; new runs appear as they finish." if live
              else f"Static snapshot of {data.get('folder', '')}. For a live view while the "
                   f"sweep runs: sim2radar dashboard {data.get('folder', 'SWEEP')} --serve")
    body = _BODY.format(
        title=html.escape(f"Sweep {data.get('name', '')}"), live_line=html.escape(live_line),
        banner_kind=html.escape(str(banner.get("kind", "unknown"))),
        banner_text=html.escape(str(banner.get("text", ""))), footer=html.escape(footer))
    poll_ms = int(round(1000 * poll_s)) if live else 0
    return "\n".join([
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f'<meta http-equiv="Content-Security-Policy" content="{html.escape(csp)}">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{html.escape('sim2radar sweep ' + str(data.get('name', '')))}</title>",
        f"<style>{_CSS}</style>",
        f'<script type="text/javascript">{_plotly_js()}</script>',
        "</head><body>",
        body,
        f'<script type="application/json" id="dashboard-data">{_script_json(data)}</script>',
        f'<script type="application/json" id="dashboard-live">'
        f'{_script_json({"poll_ms": poll_ms})}</script>',
        f"<script>{_JS}</script>",
        "</body></html>",
    ])


# ---------------------------------------------------------------------------------------------
# Explicit I/O
# ---------------------------------------------------------------------------------------------
def write_dashboard(folder: str | os.PathLike, out_path: str | os.PathLike) -> Path:
    """Write the static dashboard of the sweep in ``folder`` to ``out_path`` (atomically: a
    temporary file, then a rename). Returns ``out_path``.

    Raises
    ------
    SweepFolderError — see :func:`load_sweep`.
    """
    page = render_html(dashboard_data(load_sweep(folder)))
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp{os.getpid()}")
    tmp.write_text(page, encoding="utf-8")
    os.replace(tmp, out)
    return out


def _check_loopback(host: str) -> None:
    if host == "localhost":
        return
    try:
        loopback = ipaddress.ip_address(host).is_loopback
    except ValueError:
        loopback = False
    if not loopback:
        raise ValueError(f"host {host!r}: the dashboard serves on a loopback address only "
                         "(127.0.0.1); to view it from another machine, forward the port "
                         "(ssh -L PORT:127.0.0.1:PORT)")


#: Host names a request to the live dashboard may carry (any port): a page of another site
#: that resolves its own name to 127.0.0.1 (DNS rebinding) sends its own name and is refused
LOOPBACK_HOST_NAMES = ("127.0.0.1", "localhost", "[::1]")


def _host_name(header: str | None) -> str | None:
    """The host of a ``Host`` header without its port, lower-cased (``[::1]`` keeps its
    brackets); None for a missing or malformed header."""
    if not header:
        return None
    value = header.strip().lower()
    if value.startswith("["):  # [v6]:port
        end = value.find("]")
        if end < 0:
            return None
        name, rest = value[:end + 1], value[end + 1:]
    else:
        name, sep, port = value.partition(":")
        rest = sep + port
    if rest and not (rest.startswith(":") and rest[1:].isdigit()):
        return None
    return name


def allowed_host(header: str | None, bind_host: str = "127.0.0.1") -> bool:
    """Whether a request's ``Host`` header names this loopback server: ``127.0.0.1``,
    ``localhost``, ``[::1]`` or the address it is bound to, with or without a port."""
    name = _host_name(header)
    bind = f"[{bind_host}]" if ":" in bind_host else bind_host
    return name is not None and name in (*LOOPBACK_HOST_NAMES, bind.lower())


class DashboardServer:
    """The live dashboard of one sweep folder on a loopback address.

    ``/`` is the live page, ``/data.json`` :func:`dashboard_data` of the folder as it is now
    (re-read when one of its files changed; 503 with ``{"error"}`` while it cannot be read);
    anything else is 404. A request whose ``Host`` header is not a loopback name
    (:func:`allowed_host`: ``127.0.0.1``, ``localhost`` or ``[::1]``, any port) gets 403 with a
    one-line body: a web page cannot read the dashboard by pointing its own domain at
    127.0.0.1 (DNS rebinding). Requests are served by a
    :class:`~http.server.ThreadingHTTPServer` in a daemon thread.

    Parameters
    ----------
    folder : the sweep folder.
    host : a loopback address (anything else is refused).
    port : TCP port; 0 picks a free one (see :attr:`port`).
    poll_s : seconds between the page's polls [s].
    """

    def __init__(self, folder: str | os.PathLike, host: str = "127.0.0.1", port: int = 0,
                 poll_s: float = POLL_S) -> None:
        _check_loopback(host)
        if not poll_s > 0:
            raise ValueError(f"poll_s must be > 0, got {poll_s}")
        self.folder = Path(folder)
        self.poll_s = float(poll_s)
        self._lock = threading.Lock()
        self._cache: tuple[Any, int, bytes] | None = None  # (signature, status, JSON body)
        self._last_good: dict[str, Any] | None = None
        self._thread: threading.Thread | None = None
        server = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802  (http.server's name)
                path = self.path.split("?", 1)[0]
                host = self.headers.get("Host")
                if not allowed_host(host, server.host):
                    why = (f"forbidden: Host {host!r} is not this loopback server; open "
                           f"http://127.0.0.1:{server.port}/\n")
                    self._send(403, "text/plain; charset=utf-8", why.encode("utf-8"))
                elif path in ("/", "/index.html"):
                    self._send(200, "text/html; charset=utf-8", server.page().encode("utf-8"))
                elif path == "/data.json":
                    status, body = server.data_json()
                    self._send(status, "application/json", body)
                else:
                    self._send(404, "text/plain; charset=utf-8", b"not found\n")

            def _send(self, status: int, ctype: str, body: bytes) -> None:
                self.send_response(status)
                self.send_header("Content-Type", ctype)
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, format: str, *args: Any) -> None:  # noqa: A002
                pass  # quiet: the CLI prints the URL, not every poll

        self._httpd = ThreadingHTTPServer((host, int(port)), Handler)
        self._httpd.daemon_threads = True

    @property
    def host(self) -> str:
        return str(self._httpd.server_address[0])

    @property
    def port(self) -> int:
        return int(self._httpd.server_address[1])

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    def _signature(self) -> tuple:
        sig = []
        paths = [self.folder / f for f in FILES.values()]
        gap_dir = self.folder / "gap"
        if gap_dir.is_dir():
            paths += sorted(p for p in gap_dir.iterdir() if p.suffix == ".png")
        for p in paths:
            try:
                st = p.stat()
                sig.append((str(p), st.st_mtime_ns, st.st_size))
            except OSError:
                sig.append((str(p), None, None))
        return tuple(sig)

    def data_json(self) -> tuple[int, bytes]:
        """HTTP status and body of ``/data.json`` (re-read only when a file changed)."""
        with self._lock:
            sig = self._signature()
            if self._cache is not None and self._cache[0] == sig:
                return self._cache[1], self._cache[2]
            try:
                data = dashboard_data(load_sweep(self.folder, require_runs=False))
                status, doc = 200, data
                self._last_good = data
            except ValueError as exc:
                status, doc = 503, {"error": str(exc)}
            body = json.dumps(doc, allow_nan=False, ensure_ascii=False).encode("utf-8")
            self._cache = (sig, status, body)
            return status, body

    def page(self) -> str:
        """The live page with the folder's current data (or its last readable state)."""
        status, body = self.data_json()
        data = json.loads(body) if status == 200 else (
            self._last_good or _error_data(self.folder, json.loads(body)["error"]))
        return render_html(data, live=True, poll_s=self.poll_s)

    def start(self) -> DashboardServer:
        """Serve in a daemon thread (no-op when already serving)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._httpd.serve_forever,
                                            kwargs={"poll_interval": 0.1},
                                            name=f"dashboard:{self.port}", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and close the socket (idempotent)."""
        if self._thread is not None:
            self._httpd.shutdown()
            self._thread.join(timeout=5)
            self._thread = None
        self._httpd.server_close()

    def __enter__(self) -> DashboardServer:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()


def serve_dashboard(folder: str | os.PathLike, host: str = "127.0.0.1", port: int = 0, *,
                    poll_s: float = POLL_S) -> DashboardServer:
    """Serve the live dashboard of ``folder``; returns the started :class:`DashboardServer`
    (``.url``, ``.stop()``; also a context manager).

    The folder is checked first (:func:`load_sweep` with ``require_runs=False``: a sweep whose
    first run has not finished is shown with 0 runs), so a wrong path fails here, not in the
    browser.

    Raises
    ------
    SweepFolderError — the folder cannot be read; ValueError — ``host`` is not a loopback
    address; OSError — the port is taken.
    """
    load_sweep(folder, require_runs=False)
    return DashboardServer(folder, host, port, poll_s).start()
