"""Two sweeps side by side: the comparison page's data (pure) and its figures.

    compare_data(a, b) -> dict      what the comparison page shows, JSON-able

Per condition and real-data fraction that both sweeps ran: each sweep's mean AP with its
Student-t interval over trials, and per non-baseline condition each sweep's paired difference
to its own baseline (Δ, with the sweep's unadjusted t-interval) and the difference of the two
Δs, B minus A, with Welch's interval. Beside them: the settings that differ between the two
``sweep.json`` files (profile, seeds, datasets and their content keys, code commit, package
versions, detector configs) and the conditions, fractions and cells only one sweep has.

Statistics
    The two sweeps are independent experiments, so the difference of their Δs is judged with
    the two-sample Welch interval (Welch 1947, *Biometrika* 34, 28–35; degrees of freedom by
    Welch–Satterthwaite, Satterthwaite 1946, *Biometrics Bulletin* 2, 110–114)::

        se_X  = sd_X / sqrt(n_X)                   sd_X: the sweep's sd of its paired Δs
        d     = Δ_B − Δ_A,   se = sqrt(se_A² + se_B²)
        df    = se⁴ / (se_A⁴ / (n_A − 1) + se_B⁴ / (n_B − 1))
        d ± t(1 − α/2, df) · se

    It needs two pairs in each sweep. Where both sweeps used the same trial seeds their trials
    share real subsets, and a paired interval would be narrower; the Welch interval does not
    assume that (it is conservative when the sweeps' trials are positively correlated). The
    mean AP of a cell has the one-sample t-interval of its trials' values, and the AP
    difference of a cell (B − A) the same Welch interval on the two cells' values.
    Intervals are at the first sweep's ``1 − alpha`` (95 % by default), not adjusted for the
    number of cells compared.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

from sim2radar.experiment.dashboard.data import banner
from sim2radar.experiment.dashboard.labels import colour, metric_label, num, pct, signed
from sim2radar.experiment.dashboard.reading import SweepData, conditions_of
from sim2radar.experiment.folder import SweepFolder
from sim2radar.experiment.profiles import BASELINE
from sim2radar.experiment.report import condition_label
from sim2radar.experiment.stats import DEFAULT_METRIC, sweep_stats
from sim2radar.fileio import jsonable

__all__ = ["compare_data", "settings_diff", "welch_interval"]

#: multiplicative x offset between the two sweeps on the log fraction axis
_DODGE = 0.03
#: ``sweep.json`` fields left out of the settings comparison: the sweep's name, and the
#: pre-trainings' fitted intensity maps (numbers fitted per run, not settings)
_NOT_SETTINGS = ("name", "intensity_match")
#: a setting's value where a sweep has no such key
_ABSENT = "(absent)"
#: the settings table's groups, in order: (dotted-key prefix, group)
_GROUPS = (("profile.", "profile"), ("conditions", "grid"), ("fractions", "grid"),
           ("trials", "grid"), ("metric", "grid"), ("n_runs", "grid"), ("n_pretrains", "grid"),
           ("run seeds", "seeds"), ("datasets.", "datasets"), ("real_", "datasets"),
           ("provenance.git", "code"), ("provenance.code", "code"),
           ("settings_digest", "settings"), ("settings.", "settings"),
           ("preregistration", "settings"), ("provenance.versions", "versions"),
           ("provenance.configs", "detector configs"))


def _t_ppf(q: float, df: float) -> float:
    from scipy import stats as sps

    return float(sps.t.ppf(q, df))


def _mean_interval(values: Sequence[float], alpha: float) -> dict[str, Any]:
    """Mean, sample sd and the two-sided ``1 - alpha`` Student-t interval of the mean of
    ``values`` (None where undefined: no value, or one)."""
    n = len(values)
    mean = sum(values) / n if n else None
    sd = (math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1)) if n > 1 else None)
    lo = hi = None
    if sd is not None:
        half = _t_ppf(1 - alpha / 2, n - 1) * sd / math.sqrt(n)
        lo, hi = mean - half, mean + half
    return {"mean": mean, "sd": sd, "n": n, "ci": [lo, hi]}


def welch_interval(mean_a: float | None, sd_a: float | None, n_a: int, mean_b: float | None,
                   sd_b: float | None, n_b: int, alpha: float = 0.05) -> dict[str, Any]:
    """The difference ``mean_b - mean_a`` of two independent means with its two-sided
    ``1 - alpha`` Welch interval (see the module docstring; Welch 1947, Satterthwaite 1946).

    Parameters
    ----------
    mean_a, sd_a, n_a : sample A's mean, sample standard deviation (ddof 1) and size.
    mean_b, sd_b, n_b : the same of sample B.
    alpha : 1 - the interval's level.

    Returns
    -------
    dict — ``diff`` (None without both means), ``ci`` ([lo, hi]; None bounds with fewer than
    two values in a sample or no spread in either), ``df`` (Welch–Satterthwaite), ``note``
    (why there is no interval; None with one).
    """
    if mean_a is None or mean_b is None:
        return {"diff": None, "ci": [None, None], "df": None, "note": "not in both sweeps"}
    diff = mean_b - mean_a
    if n_a < 2 or n_b < 2 or sd_a is None or sd_b is None:
        return {"diff": diff, "ci": [None, None], "df": None,
                "note": "fewer than 2 values in a sweep"}
    va, vb = sd_a ** 2 / n_a, sd_b ** 2 / n_b
    if va + vb <= 0:
        return {"diff": diff, "ci": [None, None], "df": None,
                "note": "no spread in either sweep"}
    # Welch–Satterthwaite degrees of freedom (Satterthwaite 1946; Welch 1947)
    df = (va + vb) ** 2 / (va ** 2 / (n_a - 1) + vb ** 2 / (n_b - 1))
    half = _t_ppf(1 - alpha / 2, df) * math.sqrt(va + vb)
    return {"diff": diff, "ci": [diff - half, diff + half], "df": df, "note": None}


def _metric(data: SweepData) -> str:
    return str((data.stats or {}).get("metric") or (data.sweep.metric if data.sweep is not None else "")
               or DEFAULT_METRIC)


def _stats(data: SweepData, metric: str) -> tuple[dict[str, Any], str | None]:
    """The sweep's statistics on ``metric``: its own, or (another metric) recomputed from its
    runs without the bootstrap, with a warning."""
    stats = data.stats or {}
    if _metric(data) == metric and stats:
        return dict(stats), None
    conds = conditions_of(data.sweep, data.runs)
    if not data.runs:
        return {"cells": [], "comparisons": [], "alpha": 0.05}, None
    return (sweep_stats(data.runs, metric, conditions=conds, n_resamples=0),
            f"{data.folder}: its metric is {metric_label(_metric(data))}; compared on "
            f"{metric_label(metric)}, recomputed from its runs.parquet")


def _key(fraction: Any) -> float:
    return round(float(fraction), 9)


def _present(stats: Mapping[str, Any]) -> dict[tuple[str, float], Mapping[str, Any]]:
    """The cells with at least one run (finished or failed), by (condition, fraction)."""
    return {(str(c["condition"]), _key(c["fraction"])): c for c in stats.get("cells") or []
            if int(c.get("n") or 0) + int(c.get("n_failed") or 0) > 0}


def _comparisons(stats: Mapping[str, Any]) -> dict[tuple[str, float], Mapping[str, Any]]:
    return {(str(c["condition"]), _key(c["fraction"])): c
            for c in stats.get("comparisons") or []}


def _side(data: SweepData) -> dict[str, Any]:
    """One sweep as the comparison page names it."""
    doc = data.sweep
    profile = doc.profile if doc is not None else {}
    prov = doc.provenance if doc is not None else {}
    return {"name": (doc.name if doc is not None else "") or data.folder.name,
            "folder": str(data.folder), "profile": profile.get("name"),
            "created_at": doc.created_at if doc is not None else None,
            "metric": _metric(data), "runs": len(data.runs),
            "failed": sum(r.get("status") == "failed" for r in data.runs),
            "git": prov.get("git") if isinstance(prov.get("git"), str) else None,
            "banner": banner(data.sweep)}


def _ci_text(ci: Sequence[Any], digits: int = 1) -> str:
    lo, hi = (list(ci or []) + [None, None])[:2]
    return "" if num(lo) is None or num(hi) is None else f" [{lo:.{digits}f}, {hi:.{digits}f}]"


def _signed_ci(ci: Sequence[Any]) -> str:
    lo, hi = (list(ci or []) + [None, None])[:2]
    return "" if num(lo) is None or num(hi) is None else f" [{signed(lo)}, {signed(hi)}]"


def _mean_text(m: Mapping[str, Any]) -> str:
    if m.get("mean") is None:
        return "—"
    return f"{m['mean']:.1f}{_ci_text(m.get('ci'))} (n {m['n']})"


# ------------------------------------------------------------------------------ settings
def _flatten(doc: Any, prefix: str = "") -> dict[str, str]:
    """Dotted key -> the value as compact JSON; a list is one value."""
    if isinstance(doc, Mapping) and doc:
        out: dict[str, str] = {}
        for k, v in doc.items():
            out.update(_flatten(v, f"{prefix}.{k}" if prefix else str(k)))
        return out
    return {prefix: json.dumps(jsonable(doc), sort_keys=True, ensure_ascii=False)}


def _settings_of(data: SweepData) -> dict[str, str] | None:
    """A sweep's settings as dotted key -> JSON text: ``sweep.json`` less its name, its
    fitted intensity maps and its time stamps (``*_at``), and the trial seeds of its runs."""
    if data.sweep is None:
        return None
    written = data.sweep.model_dump(mode="json")          # the fields its file holds
    flat = {k: v for k, v in _flatten({k: v for k, v in written.items()
                                       if k not in _NOT_SETTINGS}).items()
            if not k.rsplit(".", 1)[-1].endswith("_at")}
    seeds = {int(r["trial"]): r.get("seed") for r in data.runs if r.get("trial") is not None}
    flat["run seeds (runs.parquet: trial -> seed)"] = json.dumps(
        {str(t): seeds[t] for t in sorted(seeds)})
    return flat


def _group(key: str) -> tuple[int, str]:
    for i, (prefix, name) in enumerate(_GROUPS):
        if key.startswith(prefix):
            return i, name
    return len(_GROUPS), "other"


def settings_diff(a: SweepData, b: SweepData) -> dict[str, Any]:
    """The settings that differ between two sweeps: ``sweep.json`` flattened to dotted keys
    (profile, grid, datasets with their paths and content keys, code commit, settings
    digest, package versions, detector configs; lists compared whole), without the name, the
    fitted intensity maps and the time stamps, plus each sweep's trial seeds from its runs.

    Returns
    -------
    dict — ``rows`` ([group, key, A's value, B's value] as compact JSON, grouped; "(absent)"
    where a sweep lacks the key), ``n_compared``, ``n_same``, ``note`` (what was compared, or
    why nothing was: a missing ``sweep.json``).
    """
    sa, sb = _settings_of(a), _settings_of(b)
    if sa is None or sb is None:
        missing = " and ".join(str(SweepFolder(d.folder).sweep_json) for d, s in ((a, sa), (b, sb))
                               if s is None)
        return {"rows": [], "n_compared": 0, "n_same": 0,
                "note": f"{missing} not found: the settings cannot be compared."}
    keys = sorted(set(sa) | set(sb), key=lambda k: (_group(k)[0], k))
    differ = [k for k in keys if sa.get(k) != sb.get(k)]
    return {"rows": [[_group(k)[1], k, sa.get(k, _ABSENT), sb.get(k, _ABSENT)] for k in differ],
            "n_compared": len(keys), "n_same": len(keys) - len(differ),
            "note": (f"{len(differ)} of {len(keys)} settings differ (sweep.json, flattened; "
                     "its name, the pre-trainings' fitted intensity maps and the time stamps "
                     "are left out; the trial seeds are read from runs.parquet).")}


# ------------------------------------------------------------------------------- figures
def _fraction_axis(fractions: Sequence[float]) -> dict[str, Any]:
    ticks = [100 * f for f in fractions] or [5, 10, 25, 50, 100]
    return {"type": "log", "title": {"text": "real data [% of the train split]"},
            "tickvals": ticks, "ticktext": [f"{t:g} %" for t in ticks],
            "range": [math.log10(min(ticks)) - 0.12, math.log10(max(ticks)) + 0.12]}


#: how each sweep is drawn: (line dash, marker symbol)
_STYLE = {"a": ("solid", "circle"), "b": ("dash", "square-open")}


def _error_y(values: Sequence[tuple[Sequence[Any], float]], width: int) -> dict[str, Any]:
    """Plotly's asymmetric error bars of ``(interval, value)`` pairs (a missing bound: 0)."""
    up, down = [], []
    for ci, y in values:
        lo, hi = (list(ci or []) + [None, None])[:2]
        up.append(hi - y if num(hi) is not None else 0.0)
        down.append(y - lo if num(lo) is not None else 0.0)
    return {"type": "data", "symmetric": False, "array": up, "arrayminus": down,
            "visible": True, "width": width}


def _ap_figure(cells: Sequence[Mapping[str, Any]], conds: Sequence[str], names: Mapping,
               fractions: Sequence[float], metric: str, level: str) -> dict[str, Any]:
    """Mean AP per condition and fraction in both sweeps (A solid circles, B dashed open
    squares) with their t-intervals: a ``mean`` trace per sweep and condition
    (``meta.sweep`` ``a``/``b``)."""
    import plotly.graph_objects as go

    fig = go.Figure()
    for cond in conds:
        mine = [c for c in cells if c["condition"] == cond]
        for side, dx in (("a", 1 - _DODGE), ("b", 1 + _DODGE)):
            pts = [c for c in mine if c[side]["mean"] is not None]
            dash, symbol = _STYLE[side]
            fig.add_trace(go.Scatter(
                x=[100 * c["fraction"] * dx for c in pts], y=[c[side]["mean"] for c in pts],
                error_y=_error_y([(c[side]["ci"], c[side]["mean"]) for c in pts], 4),
                mode="lines+markers", name=f"{condition_label(cond)} — {names[side]}",
                legendgroup=cond, line={"color": colour(cond, conds), "dash": dash,
                                        "width": 2.2},
                marker={"color": colour(cond, conds), "symbol": symbol, "size": 9,
                        "line": {"width": 2}},
                customdata=[[pct(c["fraction"]), c[side]["n"], _ci_text(c[side]["ci"], 2)]
                            for c in pts],
                meta={"role": "mean", "sweep": side, "condition": cond},
                hovertemplate=(f"<b>{html.escape(condition_label(cond))}</b>, "
                               f"{html.escape(names[side])} %{{customdata[0]}}<br>mean %{{y:.2f}}"
                               f"%{{customdata[2]}} ({level} CI), %{{customdata[1]}} trial(s)"
                               "<extra></extra>")))
    fig.update_layout(
        template="plotly_white", height=460, margin={"l": 60, "r": 20, "t": 60, "b": 55},
        title={"text": f"{metric_label(metric)}: mean with its {level} t-interval<br><sup>"
                       f"solid: {html.escape(names['a'])}; dashed: {html.escape(names['b'])}"
                       "</sup>"},
        xaxis=_fraction_axis(fractions),
        yaxis={"title": {"text": f"{metric_label(metric)} [%]"}, "rangemode": "tozero"},
        legend={"orientation": "h", "y": -0.2})
    if not cells:
        fig.add_annotation(text="no condition and fraction that both sweeps ran", x=0.5, y=0.5,
                           xref="paper", yref="paper", showarrow=False)
    return json.loads(fig.to_json())


def _delta_figure(deltas: Sequence[Mapping[str, Any]], conds: Sequence[str], names: Mapping,
                  fractions: Sequence[float], level: str) -> dict[str, Any]:
    """Left: each sweep's Δ to its own baseline with its t-interval (``delta`` traces,
    ``meta.sweep`` ``a``/``b``); right: the difference Δ_B − Δ_A with its Welch interval
    (``delta-diff``, one trace per condition)."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    fig = make_subplots(rows=1, cols=2, horizontal_spacing=0.1, subplot_titles=(
        f"Δ to each sweep's own {condition_label(BASELINE)} ({level} t-interval)",
        f"Δ_B − Δ_A ({level} Welch interval)"))
    others = [c for c in conds if c != BASELINE]
    for cond in others:
        mine = [d for d in deltas if d["condition"] == cond]
        col = colour(cond, conds)
        for side, dx in (("a", 1 - _DODGE), ("b", 1 + _DODGE)):
            pts = [d for d in mine if d[side]["delta"] is not None]
            dash, symbol = _STYLE[side]
            fig.add_trace(go.Scatter(
                x=[100 * d["fraction"] * dx for d in pts], y=[d[side]["delta"] for d in pts],
                error_y=_error_y([(d[side]["ci"], d[side]["delta"]) for d in pts], 4),
                mode="lines+markers", name=f"{condition_label(cond)} Δ — {names[side]}",
                legendgroup=cond, line={"color": col, "dash": dash, "width": 2},
                marker={"color": col, "symbol": symbol, "size": 8, "line": {"width": 2}},
                customdata=[[pct(d["fraction"]), d[side]["n_pairs"], _signed_ci(d[side]["ci"])]
                            for d in pts],
                meta={"role": "delta", "sweep": side, "condition": cond},
                hovertemplate=(f"{html.escape(condition_label(cond))}, "
                               f"{html.escape(names[side])} %{{customdata[0]}}<br>Δ %{{y:+.2f}}"
                               "%{customdata[2]}, %{customdata[1]} pair(s)<extra></extra>")),
                row=1, col=1)
        pts = [d for d in mine if d["diff"]["diff"] is not None]
        fig.add_trace(go.Scatter(
            x=[100 * d["fraction"] for d in pts], y=[d["diff"]["diff"] for d in pts],
            error_y=_error_y([(d["diff"]["ci"], d["diff"]["diff"]) for d in pts], 5),
            mode="lines+markers", name=f"{condition_label(cond)}: Δ_B − Δ_A",
            legendgroup=cond, line={"color": col, "width": 2.5},
            marker={"color": col, "size": 10, "symbol": "diamond"},
            customdata=[[pct(d["fraction"]), _signed_ci(d["diff"]["ci"]),
                         d["diff"]["note"] or ""] for d in pts],
            meta={"role": "delta-diff", "condition": cond},
            hovertemplate=(f"{html.escape(condition_label(cond))} %{{customdata[0]}}<br>"
                           "Δ_B − Δ_A %{y:+.2f}%{customdata[1]}<br>%{customdata[2]}"
                           "<extra></extra>")), row=1, col=2)
    for col in (1, 2):
        fig.add_hline(y=0, line={"color": "#444", "width": 1, "dash": "dot"}, row=1, col=col)
        fig.update_xaxes(**_fraction_axis(fractions), row=1, col=col)
    fig.update_yaxes(title_text="Δ AP [points]", row=1, col=1)
    fig.update_yaxes(title_text="Δ_B − Δ_A [AP points]", row=1, col=2)
    fig.update_layout(template="plotly_white", height=460,
                      margin={"l": 60, "r": 20, "t": 60, "b": 55},
                      legend={"orientation": "h", "y": -0.22})
    if not deltas:
        fig.add_annotation(text="no condition besides the baseline that both sweeps ran",
                           x=0.5, y=0.5, xref="paper", yref="paper", showarrow=False)
    return json.loads(fig.to_json())


# ------------------------------------------------------------------------------- the page
def _only(cells: Mapping, other: Mapping) -> dict[str, Any]:
    """What one sweep ran that the other did not: conditions, fractions, and cells (a
    condition and fraction both ran, but not together in the other)."""
    conds = {c for c, _ in cells} - {c for c, _ in other}
    fracs = {f for _, f in cells} - {f for _, f in other}
    lone = sorted(k for k in set(cells) - set(other) if k[0] not in conds and k[1] not in fracs)
    return {"conditions": [condition_label(c) for c in sorted(conds)],
            "fractions": [pct(f) for f in sorted(fracs)],
            "cells": [f"{condition_label(c)} at {pct(f)}" for c, f in lone]}


def compare_data(a: SweepData, b: SweepData) -> dict[str, Any]:
    """What the comparison page of sweeps A and B shows, as one JSON-able dict (pure).

    Parameters
    ----------
    a, b : :func:`~.reading.load_sweep`'s results; A is the reference (its metric and level).

    Returns
    -------
    dict with ``kind`` ("comparison"), ``a`` and ``b`` (``name``, ``folder``, ``profile``,
    ``created_at``, ``metric``, ``runs``, ``failed``, ``git``, ``banner``), ``metric``,
    ``metric_label``, ``level`` ("95 %"), ``conditions`` (``[{"name", "label", "color"}]`` of
    the shared cells), ``fractions`` (shared), ``cells`` (per shared condition and fraction:
    ``condition``, ``fraction``, ``a`` and ``b`` ``{"mean", "sd", "n", "ci"}`` of the trials'
    values, ``diff`` (:func:`welch_interval` of B − A)), ``deltas`` (per shared non-baseline
    cell: ``a`` and ``b`` ``{"delta", "ci", "sd", "n_pairs", "verdict"}``, ``diff``: Δ_B − Δ_A
    with its Welch interval), ``table`` and ``delta_table`` (``{"columns", "rows",
    "numeric"}`` of strings), ``only`` (``{"a", "b"}``: ``conditions``, ``fractions``,
    ``cells`` only that sweep ran), ``settings`` (:func:`settings_diff`), ``figures``
    (``ap``: trace ``meta.role`` ``mean`` per sweep and condition; ``delta``: ``delta`` per
    sweep and condition, ``delta-diff`` per condition), ``notes``, ``warnings``.
    No NaN anywhere.
    """
    metric = _metric(a)
    stats_a, warn_a = _stats(a, metric)
    stats_b, warn_b = _stats(b, metric)
    alpha = float(stats_a.get("alpha", 0.05))
    level = f"{100 * (1 - alpha):g} %"
    cells_a, cells_b = _present(stats_a), _present(stats_b)
    comps_a, comps_b = _comparisons(stats_a), _comparisons(stats_b)
    order = list(dict.fromkeys([*conditions_of(a.sweep, a.runs),
                                *conditions_of(b.sweep, b.runs)]))
    shared = sorted(set(cells_a) & set(cells_b),
                    key=lambda k: (order.index(k[0]) if k[0] in order else len(order), k[1]))
    conds = list(dict.fromkeys(c for c, _ in shared))
    fractions = sorted({f for _, f in shared})
    names = {"a": f"A: {_side(a)['name']}", "b": f"B: {_side(b)['name']}"}
    if names["a"][3:] == names["b"][3:]:
        names = {"a": "A", "b": "B"}

    cells, deltas, table, delta_table = [], [], [], []
    for cond, frac in shared:
        ma = _mean_interval(list(cells_a[(cond, frac)].get("values") or []), alpha)
        mb = _mean_interval(list(cells_b[(cond, frac)].get("values") or []), alpha)
        diff = welch_interval(ma["mean"], ma["sd"], ma["n"], mb["mean"], mb["sd"], mb["n"],
                              alpha)
        cells.append({"condition": cond, "fraction": frac, "a": ma, "b": mb, "diff": diff})
        table.append([condition_label(cond), pct(frac), _mean_text(ma), _mean_text(mb),
                      "—" if diff["diff"] is None else signed(diff["diff"]) + _signed_ci(
                          diff["ci"])])
        if cond == BASELINE:
            continue
        side = {}
        for key, comps in (("a", comps_a), ("b", comps_b)):
            c = comps.get((cond, frac)) or {}
            side[key] = {"delta": num(c.get("mean_diff")), "ci": list(c.get("t_ci") or
                                                                      [None, None]),
                         "sd": num(c.get("sd_diff")), "n_pairs": int(c.get("n_pairs") or 0),
                         "verdict": c.get("verdict")}
        dd = welch_interval(side["a"]["delta"], side["a"]["sd"], side["a"]["n_pairs"],
                            side["b"]["delta"], side["b"]["sd"], side["b"]["n_pairs"], alpha)
        deltas.append({"condition": cond, "fraction": frac, **side, "diff": dd})
        delta_table.append([
            condition_label(cond), pct(frac),
            *(("—" if side[k]["delta"] is None else signed(side[k]["delta"])
               + _signed_ci(side[k]["ci"])) + f" ({side[k]['n_pairs']} pairs, "
              f"{side[k]['verdict'] or '—'})" for k in ("a", "b")),
            "—" if dd["diff"] is None else signed(dd["diff"]) + _signed_ci(dd["ci"])
            + ("" if dd["note"] is None else f" ({dd['note']})")])

    notes = [
        f"Mean AP: the mean of a cell's finished trials with its {level} Student-t interval; "
        f"B − A: the difference of the two cells' means with its {level} Welch interval.",
        f"Δ: each sweep's paired difference to its own {condition_label(BASELINE)} (condition "
        f"minus baseline of the same trial) with the sweep's unadjusted {level} t-interval; "
        f"Δ_B − Δ_A: the difference of the two Δs with its {level} Welch interval (the sweeps "
        "are independent experiments; Welch 1947, Satterthwaite 1946). Where it excludes 0, "
        "the condition's advantage over its baseline differs between the sweeps at that "
        "fraction. Intervals are not adjusted for the number of cells compared.",
    ]
    warnings = [w for w in (warn_a, warn_b) if w]
    if alpha != float(stats_b.get("alpha", alpha)):
        warnings.append(f"the sweeps' statistics use different alpha ({alpha:g} and "
                        f"{float(stats_b['alpha']):g}): every interval here is at {level}")
    return jsonable({
        "kind": "comparison", "a": _side(a), "b": _side(b),
        "names": names, "metric": metric, "metric_label": metric_label(metric),
        "level": level,
        "conditions": [{"name": c, "label": condition_label(c), "color": colour(c, conds)}
                       for c in conds],
        "fractions": fractions, "cells": cells, "deltas": deltas,
        "table": {"columns": ["condition", "real data", f"{names['a']}: mean [{level} CI]",
                              f"{names['b']}: mean [{level} CI]", f"B − A [{level} CI]"],
                  "rows": table, "numeric": [False, True, True, True, True]},
        "delta_table": {"columns": ["condition", "real data", f"{names['a']}: Δ [{level} CI]",
                                    f"{names['b']}: Δ [{level} CI]",
                                    f"Δ_B − Δ_A [{level} Welch CI]"],
                        "rows": delta_table, "numeric": [False, True, True, True, True]},
        "only": {"a": _only(cells_a, cells_b), "b": _only(cells_b, cells_a)},
        "settings": settings_diff(a, b),
        "figures": {"ap": _ap_figure(cells, conds, names, fractions, metric, level),
                    "delta": _delta_figure(deltas, conds, names, fractions, level)},
        "notes": notes,
        "warnings": [*warnings, *(f"A: {w}" for w in a.warnings),
                     *(f"B: {w}" for w in b.warnings)],
    })
