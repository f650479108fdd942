"""The dashboard's runs: the runs table and each run's own view (pure).

    runs_table(runs, metric, sweep_name) -> dict    the table, one row per run
    run_ids(runs) -> list[str]                      each run's id (its run_key)
    run_folder(run, sweep_name) -> str              a run's folder relative to its sweep
    run_views(runs, pretrainings, stats, metric, sweep_folder) -> dict
                                                    each run's view: settings, learning curve,
                                                    final APs, its pre-training's check

A run's view is what an experiment tracker shows for one run: its settings, its learning
curve (per-epoch loss and validation AP), its final APs beside its cell's mean, its paired
difference to the baseline of the same trial, the check of the pre-training it loaded
(matched by ``pretrain_key``) and its folder. The page opens it by clicking the run's row
(``#run=<id>``); the live server also at ``/run/<id>``.
"""

from __future__ import annotations

import posixpath
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sim2radar.experiment.dashboard.figures import run_layout, run_traces
from sim2radar.experiment.dashboard.labels import fmt, metric_label, num, pct, signed
from sim2radar.experiment.profiles import BASELINE
from sim2radar.experiment.report import condition_label
from sim2radar.experiment.stats import AP_METRICS
from sim2radar.fileio import jsonable

__all__ = ["run_folder", "run_folders", "run_ids", "run_views", "runs_table"]

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
    *((m, metric_label(m).replace(" @ IoU ", " @"), "ap") for m in AP_METRICS),
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


def run_folders(runs: Sequence[Mapping[str, Any]], sweep_name: str,
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


def runs_table(runs: Sequence[Mapping[str, Any]], metric: str,
               sweep_name: str) -> dict[str, Any]:
    """The page's runs table: ``columns`` (``[{"key", "label", "type"}]``, the sweep's metric
    first among the APs), ``rows`` (one list of raw values per run, in file order, with its
    ``run_folder``), ``ids`` (each row's :func:`run_ids` id), ``status_column``,
    ``metric_column`` and ``group_columns`` (indices of condition, fraction, trial)."""
    cols = list(_RUN_COLUMNS)
    ap_start = next(i for i, c in enumerate(cols) if c[2] == "ap")
    head = next(i for i, c in enumerate(cols) if c[0] == metric)
    cols.insert(ap_start, cols.pop(head))  # the sweep's metric first among the APs
    rows = [[run_folder(r, sweep_name) if k == "run_folder" else jsonable(r.get(k))
             for k, _, _ in cols] for r in runs]
    keys = [c[0] for c in cols]
    return {"columns": [{"key": k, "label": label, "type": t} for k, label, t in cols],
            "rows": rows, "ids": run_ids(runs), "status_column": keys.index("status"),
            "metric_column": keys.index(metric),
            "group_columns": [keys.index(k) for k in ("condition", "fraction", "trial")]}


def run_ids(runs: Sequence[Mapping[str, Any]]) -> list[str]:
    """Each run's id, in order: its ``run_key`` (the sweep keeps one row per key); a row
    without one ``<condition>-<fraction>-t<trial>``; a repeated id gets ``~2``, ``~3``, ... (so
    every row has its own view)."""
    out: list[str] = []
    seen: dict[str, int] = {}
    for r in runs:
        key = str(r.get("run_key") or "") or (
            f"{r.get('condition')}-{num(r.get('fraction')) or 0:g}-t{r.get('trial')}")
        seen[key] = seen.get(key, 0) + 1
        out.append(key if seen[key] == 1 else f"{key}~{seen[key]}")
    return out


def _seconds(v: Any) -> str:
    f = num(v)
    if f is None:
        return "—"
    return f"{f / 3600:.2f} h" if f >= 3600 else f"{f / 60:.1f} min" if f >= 60 else f"{f:.1f} s"


def _settings(r: Mapping[str, Any]) -> list[list[str]]:
    """[label, text] rows of a run's settings and outcome."""
    cond = str(r.get("condition"))
    fraction = num(r.get("fraction"))
    epochs, steps = r.get("epochs"), r.get("steps")
    per_epoch = (f" ({int(steps) / int(epochs):g} per epoch)"
                 if isinstance(epochs, int) and isinstance(steps, int) and epochs > 0 else "")
    return [
        ["condition", f"{condition_label(cond)} ({cond})"],
        ["real data", "—" if fraction is None else f"{pct(fraction)} of the train split"],
        ["trial", fmt(r.get("trial"))],
        ["seed", str(r.get("seed")) if r.get("seed") is not None else "—"],
        ["real frames", fmt(r.get("n_real_frames"))],
        ["sim frames (its pre-training)", fmt(r.get("n_sim_frames"))],
        ["sim : real", "—" if num(r.get("sim_real_ratio")) is None
         else f"{num(r.get('sim_real_ratio')):.1f} : 1"],
        ["epochs", fmt(epochs)],
        ["optimiser steps", fmt(steps) + per_epoch],
        ["wall time", _seconds(r.get("wall_time_s"))],
        ["device", str(r.get("device") or "—")],
        ["status", str(r.get("status") or "—")],
        ["finished (UTC)", str(r.get("finished_at") or "—")],
        ["run key", str(r.get("run_key") or "—")],
        ["pre-training key", str(r.get("pretrain_key") or "—")],
    ]


def _cell_values(runs: Sequence[Mapping[str, Any]], cond: str, fraction: float | None,
                 key: str) -> list[float]:
    """The finished runs' values of ``key`` in one cell (every AP, not only the metric)."""
    return [num(r.get(key)) for r in runs
            if r.get("condition") == cond and num(r.get("fraction")) == fraction
            and r.get("status") != "failed" and num(r.get(key)) is not None]


def _aps(r: Mapping[str, Any], runs: Sequence[Mapping[str, Any]], metric: str,
         ) -> dict[str, Any]:
    """The run's final APs (the sweep's metric first) beside its cell's mean ± sd."""
    cond, fraction = str(r.get("condition")), num(r.get("fraction"))
    rows, values = [], {}
    for key in (metric, *(m for m in AP_METRICS if m != metric)):
        v = num(r.get(key))
        values[key] = v
        cell = _cell_values(runs, cond, fraction, key)
        mean = sum(cell) / len(cell) if cell else None
        sd = ((sum((x - mean) ** 2 for x in cell) / (len(cell) - 1)) ** 0.5
              if len(cell) > 1 else None)
        cell_text = ("—" if mean is None else f"{mean:.2f}" if sd is None
                     else f"{mean:.2f} ± {sd:.2f}") + (f" ({len(cell)} runs)" if cell else "")
        rows.append([metric_label(key) + (" (the sweep's metric)" if key == metric else ""),
                     "—" if v is None else f"{v:.2f}", cell_text])
    return {"columns": ["AP [%] (test split)", "this run", "its cell: mean ± sd"],
            "rows": rows, "numeric": [False, True, True], "values": values}


def _delta(r: Mapping[str, Any], stats: Mapping[str, Any]) -> str | None:
    """The run's paired difference to the baseline of its trial and fraction, one line."""
    cond, fraction, trial = str(r.get("condition")), num(r.get("fraction")), r.get("trial")
    if cond == BASELINE or fraction is None:
        return None
    for c in stats.get("comparisons") or []:
        if c.get("condition") == cond and num(c.get("fraction")) == fraction:
            pairs = dict(zip(c.get("trials") or [], c.get("differences") or [], strict=False))
            if trial in pairs:
                return (f"Δ to {condition_label(BASELINE)} of trial {trial} at {pct(fraction)}: "
                        f"{signed(pairs[trial], 2)} AP points (the cell's mean Δ "
                        f"{signed(c.get('mean_diff'), 2)} over {c.get('n_pairs')} pair(s))")
            return (f"no paired difference: the {condition_label(BASELINE)} run of trial "
                    f"{trial} at {pct(fraction)} has not finished, or this run failed")
    return None


def _pretraining_of(r: Mapping[str, Any], pretrainings: Sequence[Mapping[str, Any]],
                    ) -> tuple[Mapping[str, Any] | None, str]:
    """The pre-training a run loaded and how it was found: by ``pretrain_key``, or (a
    ``runs.parquet`` without one) the only pre-training of the run's condition and trial."""
    key = r.get("pretrain_key")
    if key:
        found = next((p for p in pretrainings if p.get("pretrain_key") == key), None)
        if found is not None:
            return found, "by its pre-training key"
        return None, (f"its pre-training (key {key}) is not in pretrainings.parquet (written "
                      "before that file existed, or the pre-training is still running)")
    cond, trial, fraction = r.get("condition"), r.get("trial"), num(r.get("fraction"))
    if cond == BASELINE or not r.get("n_sim_frames"):
        return None, "none: this run trains from scratch (no pre-trained encoder)"
    match = [p for p in pretrainings if cond in (p.get("conditions") or [])
             and p.get("trial") in (None, trial)
             and num(p.get("fraction")) in (None, fraction)]
    if len(match) == 1:
        return match[0], ("matched by condition and trial (runs.parquet names no "
                          "pre-training key)")
    return None, ("not recorded (runs.parquet names no pre-training key, and "
                  f"{len(match)} pre-trainings fit its condition and trial)")


def _pretraining_rows(p: Mapping[str, Any], cond: str,
                      table: Mapping[str, Any]) -> list[list[str]]:
    """[label, text] rows of a pre-training's check (the statistics' pre-training table row,
    APs in %), for the condition ``cond`` that loads it."""
    row = next((t for t in table.get("rows") or [] if isinstance(t, Mapping)
                and t.get("id") == p.get("pretrain_id")), {})
    thr = num((table.get("thresholds") or {}).get(cond))
    met = (row.get("met") or {}).get(cond)
    loss = list(p.get("history_loss") or [])
    fraction = num(p.get("fraction"))
    return [
        ["pre-training", str(p.get("pretrain_id"))],
        ["dataset", str(p.get("sim_role") or "—")],
        ["loaded by", ", ".join(condition_label(str(c)) for c in p.get("conditions") or [])
         or "—"],
        ["trial", "shared" if p.get("trial") is None else str(p.get("trial"))],
        ["intensities matched to", "—" if fraction is None else f"{pct(fraction)} real"],
        ["sim frames", fmt(p.get("n_sim_frames"))],
        ["train AP (its own frames)", fmt(row.get("train", p.get("train_ap_3d_r40_iou03")),
                                          ".2f")],
        ["held-out sim AP", fmt(row.get("heldout", p.get("heldout_ap_3d_r40_iou03")), ".2f")
         + f" on {fmt(p.get('n_heldout_frames'))} frames"],
        ["zero-shot real AP", fmt(row.get("zero_shot", p.get("zero_shot_ap_3d_r40_iou03")),
                                  ".2f") + f" on {fmt(p.get('n_real_val_frames'))} frames"],
        ["learnability threshold (held-out)", "none declared" if thr is None else
         f"{thr:g} — {'met' if met else 'not met' if met is not None else 'unknown'}"],
        ["final loss", fmt(loss[-1], ".4f") if loss else "—"],
        ["epochs", fmt(p.get("epochs"))],
        ["wall time", _seconds(p.get("wall_time_s"))],
        ["status", str(p.get("status") or "—") + (f": {p.get('error')}" if p.get("error")
                                                  else "")],
        ["checkpoint", str(p.get("checkpoint") or "—")],
    ]


def _title(r: Mapping[str, Any]) -> str:
    fraction = num(r.get("fraction"))
    return (f"{condition_label(str(r.get('condition')))} · "
            f"{'—' if fraction is None else pct(fraction)} real · trial {r.get('trial')}")


def run_views(runs: Sequence[Mapping[str, Any]], pretrainings: Sequence[Mapping[str, Any]],
              stats: Mapping[str, Any], metric: str, sweep_folder: str | Path,
              ) -> dict[str, Any]:
    """Each run's own view, keyed by its id (:func:`run_ids`).

    Parameters
    ----------
    runs : ``experiment_runs`` rows; pretrainings : ``experiment_pretrain`` rows.
    stats : the sweep's statistics (cells, comparisons, the pre-training table).
    metric : the sweep's metric (listed first among the APs).
    sweep_folder : the sweep folder (a run's folder is given relative to it and joined to it).

    Returns
    -------
    dict — ``views``: id -> ``{"id", "title", "status", "error", "settings" ([label, text]),
    "aps" ({"columns", "rows", "numeric", "values": {metric: AP [%] or None}}), "delta"
    (one line or None), "folder" (relative to the sweep), "folder_path", "checkpoint",
    "pretraining" ({"id", "how", "rows"} or None), "pretraining_note" (how it was found, or
    why there is none), "traces" (:func:`~.figures.run_traces`), "curve_note"}``; ``layout``:
    the run figure's layout (:func:`~.figures.run_layout`, once; None without a run).
    """
    folder = Path(sweep_folder)
    table = stats.get("pretrainings") if isinstance(stats.get("pretrainings"), Mapping) else {}
    views: dict[str, Any] = {}
    for rid, r in zip(run_ids(runs), runs, strict=True):
        rel = run_folder(r, folder.name)
        pre, how = _pretraining_of(r, pretrainings)
        curve = r.get("history_epoch") or r.get("history_val_epoch")
        views[rid] = {
            "id": rid, "title": _title(r), "status": str(r.get("status") or ""),
            "error": str(r.get("error") or ""), "settings": _settings(r),
            "aps": _aps(r, runs, metric), "delta": _delta(r, stats),
            "folder": rel, "folder_path": None if rel is None else (
                rel if posixpath.isabs(rel) else str(folder / rel)),
            "checkpoint": str(r.get("checkpoint") or "") or None,
            "pretraining": None if pre is None else {
                "id": str(pre.get("pretrain_id")), "how": how,
                "rows": _pretraining_rows(pre, str(r.get("condition")), table)},
            "pretraining_note": how,
            "traces": run_traces(r, pre),
            "curve_note": None if curve else "no learning curve recorded (a run that failed "
                                             "before its first epoch keeps none)",
        }
    return jsonable({"views": views, "layout": run_layout() if views else None})
