"""The dashboard's data: the page's JSON document (pure), from a sweep folder read by
:func:`~.reading.load_sweep`.

    load_sweep(folder) -> SweepData          read the sweep folder (:mod:`.reading`)
    dashboard_data(sweep) -> dict            what the page shows, JSON-able
    run_folder(run, sweep_name) -> str       a run's folder relative to its sweep (:mod:`.runs`)

The runs table and each run's own view are built in :mod:`.runs`, the sim–real gap section in
:mod:`.gap`, the figures in :mod:`.figures` and :mod:`.gap_plots`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sim2radar.experiment.dashboard.figures import (
    ap_figure,
    curves_figure,
    delta_figure,
    pretrain_check_figure,
    pretrain_loss_figure,
)
from sim2radar.experiment.dashboard.gap import gap_section
from sim2radar.experiment.dashboard.labels import colour, fmt, metric_label, num, pct, signed
from sim2radar.experiment.dashboard.reading import (
    FILES,
    PRETRAIN_COLUMNS,
    RUNS_COLUMNS,
    SweepData,
    SweepFolderError,
    conditions_of,
    load_sweep,
)
from sim2radar.experiment.dashboard.runs import run_folder, run_folders, run_views, runs_table
from sim2radar.experiment.documents import SweepDocument
from sim2radar.experiment.profiles import BASELINE
from sim2radar.experiment.report import (
    UNDECLARED,
    condition_label,
    detectability_sentences,
    domain_kind,
    results_table_rows,
)
from sim2radar.experiment.stats import DEFAULT_METRIC, DEGENERATE
from sim2radar.fileio import jsonable

__all__ = [
    "FILES",
    "PRETRAIN_COLUMNS",
    "RUNS_COLUMNS",
    "SweepData",
    "SweepFolderError",
    "banner",
    "dashboard_data",
    "error_data",
    "load_sweep",
    "run_folder",
]


def banner(sweep: SweepDocument | None) -> dict[str, str]:
    """The page's banner on the real domain: ``{"kind": "proxy" | "measured" | "undeclared" |
    "declared" | "unknown", "text"}`` from ``sweep.json`` (None: unknown)."""
    if sweep is None:
        return {"kind": "unknown", "text": "Real domain unknown: sweep.json is missing, so this "
                "page cannot say whether the 'real' data is measured radar or a proxy. Treat "
                "the results as unverified."}
    real = sweep.datasets.get("real") or {}
    domain = str(sweep.real_domain or real.get("domain") or UNDECLARED)
    kind = domain_kind(domain, sweep.real_is_proxy)
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
    sweep, prog = data.sweep, data.progress
    counts = {s: sum(r.get("status") == s for r in data.runs) for s in ("ok", "skipped",
                                                                        "failed")}
    planned = None
    if sweep is not None and sweep.held("n_runs") is not None:
        planned = sweep.n_runs
    elif sweep is not None and sweep.fractions and sweep.trials:
        planned = len(conds) * len(sweep.fractions) * sweep.trials
    total = prog.total_runs if prog is not None else planned
    finished = len(data.runs)
    total = max(int(total), finished) if total is not None else finished
    running = prog.running if prog is not None else []
    # a progress.json from before pre-trainings were counted: the planned ones (sweep.json)
    n_pre = prog.held("total_pretrainings") if prog is not None else None
    n_pre = n_pre if n_pre is not None else (sweep.n_pretrains if sweep is not None else 0)
    pre_done = max(len(data.pretrainings), prog.pretrainings_finished if prog is not None else 0)
    state = ("no run planned" if total == 0 else "complete" if finished >= total
             else "running" if finished else "pre-training" if pre_done < n_pre
             else "running" if pre_done else "not started")
    return {"finished": finished, "total": total, "ok": counts["ok"],
            "pretrainings_finished": pre_done, "pretrainings_total": max(n_pre, pre_done),
            "skipped": counts["skipped"], "failed": counts["failed"],
            "running": [r if isinstance(r, str) else json.dumps(jsonable(r)) for r in running],
            "updated_at": prog.held("updated_at") if prog is not None else None,
            "state": state}


#: summary columns shown left-aligned (text); every other column is a number
_TEXT_SUMMARY_COLUMNS = ("condition", "real data", "verdict")


def _level(stats: Mapping[str, Any]) -> str:
    """The confidence level of the statistics' intervals: ``95 %``."""
    return f"{100 * (1 - float(stats.get('alpha', 0.05))):g} %"


def _interval_headings(stats: Mapping[str, Any]) -> dict[str, str]:
    """Table 1's interval columns (:func:`~sim2radar.experiment.report.results_table_rows`'
    keys) -> the page's headings, which say which interval is which."""
    level = _level(stats)
    return {f"{level} CI": f"{level} CI (unadjusted)",
            "simultaneous CI": f"simultaneous {level} CI (Holm family)"}


def _interval_note(stats: Mapping[str, Any]) -> str:
    """The line under Table 1: which interval the Holm verdict agrees with."""
    level = _level(stats)
    note = (f"Per-fraction comparisons (secondary): p and the verdict are Holm-adjusted across "
            f"each condition's fractions. The simultaneous {level} CI (the 1 − alpha/m "
            "Student-t interval, Bonferroni over the condition's m fractions) is the interval "
            "the verdict agrees with: where it excludes 0 the verdict is a gain or loss (Holm "
            "may also call a fraction whose simultaneous interval still touches 0). The "
            f"unadjusted {level} CI is each fraction's own interval: it may exclude 0 beside "
            "\"no detectable difference\".")
    if not any("t_ci_simultaneous" in c for c in stats.get("comparisons", [])):
        note += (f" This {FILES['stats']} was written before the simultaneous interval "
                 "existed: its column shows dashes.")
    return note


def _summary_table(stats: Mapping[str, Any]) -> dict[str, Any]:
    """Table 1 (paper) as strings: one row per (non-baseline condition, fraction), with the
    MDE beside Δ, P(improved) beside k/n
    (:func:`~sim2radar.experiment.report.results_table_rows`), its interval columns headed
    ``95 % CI (unadjusted)`` and ``simultaneous 95 % CI (Holm family)``; ``numeric`` flags the
    right-aligned columns; ``sentences`` says what the sweep could and could not have detected
    (:func:`~sim2radar.experiment.report.detectability_sentences`); ``interval_note`` which
    interval the Holm verdict agrees with (None without a row)."""
    rows = results_table_rows(stats)
    sentences = detectability_sentences(stats)
    if not rows:
        return {"columns": [], "rows": [], "numeric": [], "sentences": sentences,
                "interval_note": None}
    cols = list(rows[0])
    headings = _interval_headings(stats)
    return {"columns": [headings.get(c, c) for c in cols],
            "rows": [[condition_label(r[c]) if c == "condition" else r[c] for c in cols]
                     for r in rows],
            "numeric": [c not in _TEXT_SUMMARY_COLUMNS for c in cols],
            "sentences": sentences, "interval_note": _interval_note(stats)}


def _p_text(v: Any) -> str:
    f = num(v)
    return "—" if f is None else "<0.001" if f < 0.001 else f"{f:.3f}"


def _pooled_mde(row: Mapping[str, Any]) -> str:
    """The pooled endpoint's MDE [AP points], or a dash with the short reason there is none."""
    mde = num(row.get("mde"))
    if mde is not None:
        return f"{mde:.1f}"
    if int(row.get("n_pairs") or 0) < 2:
        return "— (< 2 trials)"
    return "— (sd 0)" if row.get("verdict") == DEGENERATE else "—"


def _pooled_delta(row: Mapping[str, Any]) -> str:
    """Δ with its interval: ``+1.2 [−0.8, +3.2]``."""
    lo, hi = (list(row.get("t_ci") or []) + [None, None])[:2]
    ci = "" if num(lo) is None or num(hi) is None else f" [{signed(lo)}, {signed(hi)}]"
    return signed(row.get("mean_diff")) + ci


def _primary_sentence(stats: Mapping[str, Any], pooled: Sequence[Mapping[str, Any]]) -> str:
    """One line with the verdict of the pre-registered primary endpoint, e.g. "Primary
    endpoint (pre-registered): Sim Pretrain vs Baseline pooled over 5 %, 10 %, 25 %: Δ +1.2 AP
    [−0.8, +3.2] (95 % CI, 5 trials), MDE 2.9 AP at 80 % power, no detectable difference."."""
    primary = stats.get("primary") if isinstance(stats.get("primary"), Mapping) else {}
    fracs = [float(f) for f in (primary.get("fractions") or pooled[0].get("fractions") or [])]
    where = f"pooled over {', '.join(pct(f) for f in fracs)}"
    row = next((r for r in pooled if r.get("primary")), None)
    if row is None:
        name = primary.get("condition")
        why = (f"its condition, {condition_label(str(name))}, is not in this sweep" if name
               else "the profile declares no primary condition")
        return (f"Primary endpoint (pre-registered): none to report ({why}); the pooled "
                f"differences ({where}) below are diagnostics.")
    head = (f"Primary endpoint (pre-registered): {condition_label(str(row['condition']))} vs "
            f"{condition_label(BASELINE)} {where}: ")
    if num(row.get("mean_diff")) is None:
        return head + (f"no trial has finished both conditions at every one of these fractions "
                       f"yet ({row.get('verdict', 'insufficient trials')}).")
    n = int(row.get("n_pairs") or 0)
    delta = f"Δ {signed(row['mean_diff'])} AP"
    lo, hi = (list(row.get("t_ci") or []) + [None, None])[:2]
    if num(lo) is not None and num(hi) is not None:
        delta += f" [{signed(lo)}, {signed(hi)}] ({_level(stats)} CI, {n} trials)"
    else:
        delta += f" ({n} trial{'s' if n != 1 else ''}, no interval)"
    power = float((stats.get("power") or {}).get("power", 0.8))
    mde = num(row.get("mde"))
    mde_text = (f"MDE {mde:.1f} AP at {100 * power:g} % power" if mde is not None
                else f"no MDE ({row.get('mde_note') or 'fewer than 2 trials'})")
    return head + f"{delta}, {mde_text}, {row.get('verdict', '')}."


def _primary(stats: Mapping[str, Any]) -> dict[str, Any]:
    """The pooled (primary) endpoint for the page: ``sentence`` (the primary verdict, one
    line), ``note`` (how it is computed), ``columns``, ``rows`` (one per non-baseline
    condition, the primary first: condition label, ``primary``/``diagnostic``, trials,
    baseline and condition mean AP, Δ with its interval, MDE, p, d_z, k/n, verdict) and
    ``numeric`` (right-aligned columns). Empty rows and None texts for statistics without a
    ``pooled`` endpoint (a ``stats.json`` written before it)."""
    pooled = [r for r in stats.get("pooled") or [] if isinstance(r, Mapping)]
    if not pooled:
        return {"sentence": None, "note": None, "columns": [], "rows": [], "numeric": []}
    level = _level(stats)
    pooled = sorted(pooled, key=lambda r: not r.get("primary"))
    columns = ["condition", "role", "trials", condition_label(BASELINE), "condition AP",
               f"Δ [{level} CI]", "MDE", "p", "d_z", "k/n", "verdict"]
    rows = [[condition_label(str(r.get("condition"))),
             "primary" if r.get("primary") else "diagnostic", int(r.get("n_pairs") or 0),
             fmt(num(r.get("baseline_mean"))), fmt(num(r.get("condition_mean"))),
             _pooled_delta(r), _pooled_mde(r), _p_text(r.get("p")), fmt(num(r.get("d_z")),
                                                                         ".2f"),
             f"{r.get('k_improved', 0)}/{r.get('n_pairs', 0)}", str(r.get("verdict", ""))]
            for r in pooled]
    alpha = float(stats.get("alpha", 0.05))
    note = (f"Per trial, the mean of its paired differences (condition minus baseline) at the "
            f"pooled fractions, for the trials complete at all of them; then their mean with "
            f"its {level} Student-t interval and the paired t-test at alpha = {alpha:g}: one "
            "pre-registered test, no family adjustment. The other rows are diagnostics at the "
            "same unadjusted level, not further tests of the primary question.")
    return {"sentence": _primary_sentence(stats, pooled), "note": note, "columns": columns,
            "rows": rows, "numeric": [c not in ("condition", "role", "verdict")
                                      for c in columns]}


def _mean_sd(spread: Any) -> str:
    """``{"mean", "std"}`` as ``12.3 ± 1.2`` (``12.3`` without a std; ``—`` without a mean)."""
    spread = spread if isinstance(spread, Mapping) else {}
    mean, sd = num(spread.get("mean")), num(spread.get("std"))
    if mean is None:
        return "—"
    return f"{mean:.1f}" if sd is None else f"{mean:.1f} ± {sd:.1f}"


#: the pre-training summary table: (heading, right-aligned)
_PRETRAIN_SUMMARY_COLUMNS = (("condition", False), ("dataset", False),
                             ("pre-trainings", True), ("failed", True), ("train AP", True),
                             ("held-out sim AP", True), ("zero-shot real AP", True),
                             ("threshold (held-out)", False))
#: the table of every pre-training: (heading, right-aligned)
_PRETRAIN_ROW_COLUMNS = (("pre-training", False), ("dataset", False), ("conditions", False),
                         ("trial", True), ("real fraction", True), ("sim frames", True),
                         ("held-out frames", True), ("real val frames", True),
                         ("train AP", True), ("held-out sim AP", True),
                         ("zero-shot real AP", True), ("final loss", True),
                         ("threshold", False), ("status", False), ("error", False))


def _pretrain_summary_row(s: Mapping[str, Any]) -> list[Any]:
    thr = num(s.get("threshold"))
    return [condition_label(str(s.get("condition"))), str(s.get("role") or "—"),
            s.get("n"), s.get("n_failed"), _mean_sd(s.get("train")),
            _mean_sd(s.get("heldout")), _mean_sd(s.get("zero_shot")),
            "—" if thr is None else f"{thr:.1f} (met {s.get('n_met')}/{s.get('n')})"]


def _pretrain_row(r: Mapping[str, Any]) -> list[Any]:
    met = ", ".join(f"{condition_label(str(c))}: {'met' if v else 'not met'}"
                    for c, v in (r.get("met") or {}).items() if v is not None) or "—"
    fraction = num(r.get("fraction"))
    return [str(r.get("id")), str(r.get("role") or "—"),
            ", ".join(condition_label(str(c)) for c in r.get("conditions") or []) or "—",
            "shared" if r.get("trial") is None else r.get("trial"),
            "—" if fraction is None else pct(fraction), r.get("n_sim_frames"),
            r.get("n_heldout_frames"), r.get("n_real_val_frames"), fmt(num(r.get("train"))),
            fmt(num(r.get("heldout"))), fmt(num(r.get("zero_shot"))),
            fmt(num(r.get("final_loss")), ".3f"), met, str(r.get("status") or "—"),
            str(r.get("error") or "")]


def _pretrainings(stats: Mapping[str, Any], rows: Sequence[Mapping[str, Any]],
                  conds: Sequence[str]) -> dict[str, Any]:
    """The pre-trainings for the page, from the statistics' pre-training table
    (:func:`~sim2radar.experiment.learnability.pretraining_table`) and the
    ``experiment_pretrain`` rows (the loss curves): ``n``, ``n_failed``, ``note`` (what the
    checks measure), ``summary`` and ``table`` (``columns``, ``rows`` of strings and numbers,
    ``numeric``), ``figures`` (``check``: :func:`~.figures.pretrain_check_figure`, ``loss``:
    :func:`~.figures.pretrain_loss_figure`; None without a pre-training)."""
    table = stats.get("pretrainings")
    table = table if isinstance(table, Mapping) else {}
    found = [r for r in table.get("rows") or [] if isinstance(r, Mapping)]
    summary = [s for s in table.get("summary") or [] if isinstance(s, Mapping)]
    has_any = bool(found or rows)
    return {
        "n": len(found),
        "n_failed": sum(r.get("status") == "failed" for r in found),
        "note": ("3D AP (R40, IoU 0.3, %) of each pre-trained detector (encoder and head, no "
                 "fine-tuning) on its own simulated training frames, on the held-out simulated "
                 "split (worlds it never saw) and zero-shot on the real validation split. A "
                 "threshold is the pre-registered held-out sim AP a condition's pre-trainings "
                 "were expected to reach: reported, never used to select or drop a run."),
        "summary": {"columns": [c for c, _ in _PRETRAIN_SUMMARY_COLUMNS],
                    "rows": [_pretrain_summary_row(s) for s in summary],
                    "numeric": [n for _, n in _PRETRAIN_SUMMARY_COLUMNS]},
        "table": {"columns": [c for c, _ in _PRETRAIN_ROW_COLUMNS],
                  "rows": [_pretrain_row(r) for r in found],
                  "numeric": [n for _, n in _PRETRAIN_ROW_COLUMNS]},
        "figures": {"check": pretrain_check_figure({**table, "rows": found}, conds)
                    if has_any else None,
                    "loss": pretrain_loss_figure(rows, conds) if has_any else None},
    }


def _generation(data: SweepData) -> dict[str, Any]:
    datasets = []
    for role, d in (data.sweep.datasets if data.sweep is not None else {}).items():
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
                        "points_per_frame": fmt(d.get("points_per_frame_mean")),
                        "labels_per_frame": fmt(d.get("labels_per_frame_mean"), ".2f")})
    return jsonable({"datasets": datasets, "generation": gen})


def _with_datasets(config: Any, sweep: SweepDocument) -> Any:
    """A detector config as the sweep used it: its ``data.root`` is the config file's
    placeholder (each run reads the sweep's datasets), so it shows the datasets instead."""
    if not isinstance(config, Mapping) or not isinstance(config.get("data"), Mapping):
        return config
    roots = {role: d.get("path") for role, d in sweep.datasets.items()}
    return {**config, "data": {**config["data"], "root": f"(not used: the sweep's datasets "
                                                         f"{roots})"}}


def _provenance(sweep: SweepDocument | None) -> dict[str, Any] | None:
    if sweep is None:
        return None
    prov = sweep.provenance
    code = prov.get("code")
    git = prov.get("git")
    return jsonable({
        "created_at": sweep.created_at,
        "settings_fixed_at": sweep.settings_fixed_at,
        "settings_digest": sweep.settings_digest,
        "versions": prov.get("versions") or {},
        "code": code if isinstance(code, Mapping) else ({"code": code} if code else {}),
        "git": git if isinstance(git, str) else (json.dumps(jsonable(git)) if git else None),
        "configs": {k: json.dumps(jsonable(_with_datasets(v, sweep)), indent=1)
                    for k, v in (prov.get("configs") or {}).items()},
        "datasets": {role: {"path": d.get("path"), "key": d.get("key"),
                            "domain": d.get("domain")}
                     for role, d in sweep.datasets.items()},
        "profile": json.dumps(jsonable(sweep.profile), indent=1),
        "intensity_match": json.dumps(jsonable(sweep.intensity_match), indent=1)
        if sweep.intensity_match else None,
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
    ``progress`` (``finished``, ``total``, ``ok``, ``skipped``, ``failed``,
    ``pretrainings_finished``, ``pretrainings_total``, ``running``,
    ``updated_at``, ``state``), ``conditions`` (``[{"name", "label", "color"}]``),
    ``fractions``, ``figures`` (Plotly ``{"data", "layout"}`` of ``ap``, ``delta``, ``curves``;
    trace ``meta.role`` ``mean``/``trials``, ``delta``/``delta-trials``, ``loss``/``val_ap``;
    the ``delta`` error bars are the simultaneous interval the Holm verdict agrees with),
    ``primary`` (the pre-registered primary endpoint, the Δ pooled over the low-data
    fractions: ``sentence``, one line with the primary verdict; ``note``; ``columns``,
    ``rows``, one per non-baseline condition, the primary first, then the diagnostics;
    ``numeric``; empty rows and None texts without ``pooled`` in the statistics),
    ``summary`` (Table 1, secondary: ``columns`` with ``95 % CI (unadjusted)`` and
    ``simultaneous 95 % CI (Holm family)``, ``rows`` of strings with the MDE and P(improved)
    per cell, ``numeric``, ``sentences``: what the sweep could and could not detect,
    ``interval_note``: which interval the Holm verdict agrees with),
    ``pretrainings`` (``n``, ``n_failed``, ``note``, ``summary`` per condition and ``table``
    per pre-training, each ``{"columns", "rows", "numeric"}``; ``figures``: ``check`` (trace
    ``meta.role`` ``pretrain_check``, ``meta.measure`` ``heldout``/``zero_shot``/
    ``threshold``) and ``loss`` (``pretrain_loss``, one trace per pre-training that did not
    fail), None without a pre-training), ``notes``,
    ``stats_source``, ``runs`` (``columns`` ``[{"key", "label", "type"}]``, ``rows``: one
    list per run with its ``run_folder`` relative to the sweep; ``ids``: each row's run id;
    ``status_column``, ``metric_column``, ``group_columns``: indices of condition, fraction,
    trial), ``run_views`` (each run's own view by id, :func:`~.runs.run_views`),
    ``datasets``, ``generation``, ``gap`` (None without ``gap/gap.json``; its tables and
    figures, :func:`~.gap.gap_section`), ``provenance``
    (None without ``sweep.json``), ``warnings``, ``error`` (None; set by the live server when
    the folder cannot be read).
    No NaN anywhere (``json.dumps(..., allow_nan=False)`` works).
    """
    sweep_doc = sweep.sweep
    stats = sweep.stats or {"cells": [], "comparisons": [], "conditions": [], "fractions": [],
                            "notes": [], "alpha": 0.05, "metric": DEFAULT_METRIC}
    conds = list(dict.fromkeys([*stats.get("conditions", []),
                                *conditions_of(sweep.sweep, sweep.runs)]))
    if BASELINE in conds:
        conds = [BASELINE, *(c for c in conds if c != BASELINE)]
    metric = str(stats.get("metric") or (sweep_doc.metric if sweep_doc is not None else "")
                 or DEFAULT_METRIC)
    profile = sweep_doc.profile if sweep_doc is not None else {}
    gen = _generation(sweep)
    name = (sweep_doc.name if sweep_doc is not None else "") or sweep.folder.name
    folders = run_folders(sweep.runs, sweep.folder.name)
    data = {
        "name": name,
        "folder": str(sweep.folder),
        "metric": metric,
        "metric_label": metric_label(metric),
        "created_at": sweep_doc.created_at if sweep_doc is not None else None,
        "profile": profile.get("name"),
        "banner": banner(sweep.sweep),
        "progress": _progress(sweep, conds),
        "conditions": [{"name": c, "label": condition_label(c), "color": colour(c, conds)}
                       for c in conds],
        "fractions": [float(f) for f in stats.get("fractions", [])],
        "figures": {"ap": ap_figure(stats, conds, metric, folders),
                    "delta": delta_figure(stats, conds, metric),
                    "curves": curves_figure(sweep.runs, conds)},
        "primary": _primary(stats),
        "summary": _summary_table(stats),
        "pretrainings": _pretrainings(stats, sweep.pretrainings, conds),
        "notes": [str(n) for n in stats.get("notes", [])],
        "stats_source": sweep.stats_source,
        "runs": runs_table(sweep.runs, metric, sweep.folder.name),
        "run_views": run_views(sweep.runs, sweep.pretrainings, stats, metric, sweep.folder),
        "datasets": gen["datasets"],
        "generation": gen["generation"],
        "gap": gap_section(sweep.gap, sweep.gap_images),
        "provenance": _provenance(sweep.sweep),
        "warnings": list(sweep.warnings),
        "error": None,
    }
    return jsonable(data)


def error_data(folder: str | os.PathLike, message: str) -> dict[str, Any]:
    """The page's data for a folder that cannot be read (the live server's first page)."""
    data = dashboard_data(SweepData(folder=Path(folder), runs=[]))
    data["error"] = message
    return data
