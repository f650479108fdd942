"""The dashboard's data: reading a sweep folder (explicit I/O, the folder is given) and the
page's JSON document (pure).

    load_sweep(folder) -> SweepData          read the sweep folder
    dashboard_data(sweep) -> dict            what the page shows, JSON-able
    run_folder(run, sweep_name) -> str       a run's folder relative to its sweep

What the sweep folder holds (written by ``flows/run_experiment.py`` and ``sim2radar demo``)::

    runs.parquet          one ``experiment_runs`` row per training run (storage/schemas.py)
    sweep.json            profile, conditions, fractions, trials, metric, datasets (+ domain),
                          provenance (versions, code, configs)       optional: banner "unknown"
    stats.json            sim2radar.experiment.stats.sweep_statistics output (per-fraction
                          comparisons, the pooled primary endpoint, the pre-training table)
                                                                     optional: recomputed
    pretrainings.parquet  one ``experiment_pretrain`` row per pre-training, with its
                          learnability check (storage/schemas.py)    optional: none shown
    generation.json   {"datasets": [{name, role, scenes_ok, ...}]}   optional
    gap/gap.json      sim2radar gap's report, PNGs beside it          optional
    progress.json     {"total_runs", "finished", "failed", "total_pretrainings",
                      "pretrainings_finished", "running", "updated_at"}  optional

``runs.parquet`` and ``pretrainings.parquet`` are read with pyarrow and checked against the
columns the page reads (:data:`RUNS_COLUMNS`, :data:`PRETRAIN_COLUMNS`): the library does not
import the store (``sim2radar.storage``), whose layer is above it.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import os
import posixpath
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
from sim2radar.experiment.dashboard.labels import colour, metric_label, num, pct
from sim2radar.experiment.learnability import pretraining_table
from sim2radar.experiment.profiles import BASELINE, CONDITIONS
from sim2radar.experiment.report import (
    UNDECLARED,
    condition_label,
    detectability_sentences,
    domain_kind,
    results_table_rows,
)
from sim2radar.experiment.stats import (
    AP_METRICS,
    DEFAULT_METRIC,
    DEGENERATE,
    sweep_statistics,
)
from sim2radar.fileio import json_text, jsonable

__all__ = [
    "FILES",
    "PRETRAIN_COLUMNS",
    "RUNS_COLUMNS",
    "SweepData",
    "SweepFolderError",
    "dashboard_data",
    "error_data",
    "load_sweep",
    "run_folder",
]

#: files of a sweep folder the dashboard reads, by role
FILES = {"runs": "runs.parquet", "sweep": "sweep.json", "stats": "stats.json",
         "pretrainings": "pretrainings.parquet", "generation": "generation.json",
         "gap": "gap/gap.json", "progress": "progress.json"}
#: PNG file signature (PNG spec, §5.2)
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


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
    stats : dict or None — the statistics
        (:func:`~sim2radar.experiment.stats.sweep_statistics`' structure): ``stats.json`` when
        it matches the runs, else recomputed from ``runs`` and ``pretrainings``.
    stats_source : str — where ``stats`` came from, one line for the page.
    pretrainings : list of dict — ``experiment_pretrain`` rows of ``pretrainings.parquet``, in
        file order (empty: no such file).
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
    pretrainings: list[dict[str, Any]] = dataclasses.field(default_factory=list)
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
    try:
        text = json_text(path)          # or its .gz copy (a published sweep)
        if text is None:
            return None
        doc = json.loads(text)
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


#: the ``runs.parquet`` columns the dashboard reads, with the kind of value each holds. The file
#: is an ``experiment_runs`` table (declared in storage/schemas.py; the sweep flow validates it
#: before it writes the file); the library reads it without importing the store's layer, so it
#: checks here what it reads. Other columns are kept and not shown.
RUNS_COLUMNS: dict[str, str] = {
    "run_key": "text", "condition": "text", "fraction": "number", "trial": "integer",
    "seed": "integer", "n_real_frames": "integer", "n_sim_frames": "integer",
    "sim_real_ratio": "number", **dict.fromkeys(AP_METRICS, "number"),
    "epochs": "integer", "steps": "integer", "history_epoch": "integers",
    "history_loss": "numbers", "history_val_epoch": "integers", "history_val_ap": "numbers",
    "wall_time_s": "number", "device": "text", "checkpoint": "text", "status": "text",
    "error": "text", "finished_at": "text",
}
#: columns that identify a run and its outcome: never null (non-nullable in experiment_runs)
_RUN_IDENTITY = ("condition", "fraction", "trial", "status")
_RUNS_FIX = "rerun `sim2radar sweep` with the same name to rewrite it"
#: the ``pretrainings.parquet`` columns the dashboard reads (an ``experiment_pretrain`` table,
#: storage/schemas.py), with the kind of value each holds; as :data:`RUNS_COLUMNS`
PRETRAIN_COLUMNS: dict[str, str] = {
    "pretrain_id": "text", "sim_role": "text", "conditions": "texts", "trial": "integer",
    "fraction": "number", "seed": "integer", "n_sim_frames": "integer",
    "n_heldout_frames": "integer", "n_real_val_frames": "integer",
    **{f"{where}_ap_{m}_r40_iou03": "number" for where in ("train", "heldout", "zero_shot")
       for m in ("3d", "bev")},
    "epochs": "integer", "steps": "integer", "history_epoch": "integers",
    "history_loss": "numbers", "wall_time_s": "number", "status": "text", "error": "text",
}
#: columns that identify a pre-training and its outcome: never null (experiment_pretrain)
_PRETRAIN_IDENTITY = ("pretrain_id", "sim_role", "conditions", "status")
_PRETRAIN_FIX = ("rerun `sim2radar sweep` with the same name to rewrite it, or delete it (the "
                 "page then shows no pre-training)")


def _holds(arrow_type: Any, kind: str) -> bool:
    """Whether a column of ``arrow_type`` holds values of ``kind`` (:data:`RUNS_COLUMNS`'s
    kinds; ``texts``/``integers``/``numbers``: lists of them); a column of nulls only holds
    any kind."""
    import pyarrow as pa

    if kind in ("texts", "integers", "numbers"):
        return ((pa.types.is_list(arrow_type) or pa.types.is_large_list(arrow_type))
                and _holds(arrow_type.value_type, kind[:-1]))
    if pa.types.is_null(arrow_type):
        return True
    if kind == "text":
        return pa.types.is_string(arrow_type) or pa.types.is_large_string(arrow_type)
    if kind == "integer":
        return pa.types.is_integer(arrow_type)
    return pa.types.is_integer(arrow_type) or pa.types.is_floating(arrow_type)


def _read_table(path: Path, columns: Mapping[str, str], identity: Sequence[str], what: str,
                fix: str) -> list[dict[str, Any]]:
    """The rows of the Parquet file ``path``, checked against ``columns`` (name -> kind, see
    :func:`_holds`) with no null in the ``identity`` columns; ``what`` names the table
    (``experiment_runs``) and ``fix`` the remedy in the error message."""
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except Exception as exc:  # pyarrow raises ArrowInvalid / OSError for a damaged file
        raise SweepFolderError(f"{path}: not a readable Parquet file ({exc}); {fix}") from None
    missing = [c for c in columns if c not in table.column_names]
    if missing:
        raise SweepFolderError(f"{path}: column(s) {missing} missing, so it is not a sweep's "
                               f"{what} table (storage/schemas.py) or was written by another "
                               f"version; {fix}")
    for name, kind in columns.items():
        column = table.column(name)
        if not _holds(column.type, kind):
            raise SweepFolderError(f"{path}: column {name!r} has type {column.type}, not "
                                   f"{kind}; {fix}")
        if name in identity and column.null_count:
            raise SweepFolderError(f"{path}: column {name!r} has {column.null_count} null "
                                   f"value(s); {fix}")
    return table.to_pylist()


def _read_runs(folder: Path) -> list[dict[str, Any]]:
    """The rows of ``runs.parquet``, checked against :data:`RUNS_COLUMNS`."""
    return _read_table(folder / FILES["runs"], RUNS_COLUMNS, _RUN_IDENTITY, "experiment_runs",
                       _RUNS_FIX)


def _read_pretrainings(folder: Path) -> list[dict[str, Any]]:
    """The rows of ``pretrainings.parquet``, checked against :data:`PRETRAIN_COLUMNS`; none
    without the file (a sweep without pre-training, or written before the file existed)."""
    path = folder / FILES["pretrainings"]
    if not path.is_file():
        return []
    return _read_table(path, PRETRAIN_COLUMNS, _PRETRAIN_IDENTITY, "experiment_pretrain",
                       _PRETRAIN_FIX)


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


def _pretrained(conds: Sequence[str]) -> list[str]:
    """The conditions of ``conds`` that load a pre-trained encoder (a registered condition
    with a ``sim_role``), in order: those the pre-training table summarises (as
    :func:`~sim2radar.experiment.stats.sweep_statistics` does)."""
    return [c for c in conds if c in CONDITIONS and CONDITIONS[c].sim_role]


def _numbers(value: Any) -> bool:
    """Whether ``value`` is a list of finite numbers."""
    return isinstance(value, list) and all(num(v) is not None for v in value)


def _statistics_doc(sweep: Mapping[str, Any] | None, folder: Path) -> dict[str, Any]:
    """``sweep.json`` as :func:`~sim2radar.experiment.stats.sweep_statistics` reads it: its
    ``metric`` checked (default :data:`DEFAULT_METRIC`), its ``profile`` a dict whose
    ``fractions``, ``primary_fractions`` and ``learnability_thresholds`` (condition -> held-out
    sim AP [%]) hold numbers; ``{"metric": ..., "profile": {}}`` without ``sweep.json``.

    Raises
    ------
    SweepFolderError — a field of another kind, naming ``sweep.json`` and the fix.
    """
    path = folder / FILES["sweep"]
    doc = dict(sweep or {})
    metric = str(doc.get("metric") or DEFAULT_METRIC)
    if metric not in AP_METRICS:
        raise SweepFolderError(f"{path}: field 'metric' is {metric!r}, not one of "
                               f"{list(AP_METRICS)}; {_FIXES['sweep']}")
    profile = doc.get("profile")
    profile = dict(profile) if isinstance(profile, Mapping) else {}
    for where, holder in (("", doc), ("profile.", profile)):
        for key in ("fractions", "primary_fractions"):
            if holder.get(key) is not None and not _numbers(holder[key]):
                raise SweepFolderError(f"{path}: field '{where}{key}' is not a list of numbers; "
                                       f"{_FIXES['sweep']}")
    thresholds = profile.get("learnability_thresholds")
    if thresholds is not None and not (isinstance(thresholds, Mapping) and
                                       _numbers(list(thresholds.values()))):
        raise SweepFolderError(f"{path}: field 'profile.learnability_thresholds' is not an "
                               "object of numbers (condition -> held-out sim AP [%]); "
                               f"{_FIXES['sweep']}")
    if profile.get("primary_condition") is not None and not isinstance(
            profile["primary_condition"], str):
        raise SweepFolderError(f"{path}: field 'profile.primary_condition' is not a condition "
                               f"name; {_FIXES['sweep']}")
    return {**doc, "metric": metric, "profile": profile}


def _check_stats(stats: Mapping[str, Any], path: Path) -> None:
    """``stats.json`` holds the lists the page reads; ``pooled`` (the primary endpoint) and
    ``pretrainings`` (the pre-training table) are optional (a file written before them)."""
    _require(stats, ("cells", "comparisons", "conditions", "fractions"), path, "stats")
    if "pooled" in stats:
        _require(stats, ("pooled",), path, "stats")
    if "primary" in stats:
        _require(stats, ("primary",), path, "stats", dict)
    if "pretrainings" in stats:
        _require(stats, ("pretrainings",), path, "stats", dict)
        _require(stats["pretrainings"], ("rows", "summary"), path, "stats")


def _pretrainings_stale(stats: Mapping[str, Any], rows: Sequence[Mapping[str, Any]]) -> bool:
    """Whether ``stats`` lacks the pre-training table of ``rows`` (none, or one of another
    number of pre-trainings: written before the latest finished)."""
    table = stats.get("pretrainings")
    return not isinstance(table, Mapping) or len(table.get("rows") or []) != len(rows)


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
    ``runs.parquet``, otherwise computed from the runs and the pre-trainings
    (:func:`~sim2radar.experiment.stats.sweep_statistics`: a sweep still running has no
    ``stats.json``; one that was resumed may have a stale one). A ``stats.json`` without a
    pre-training table, or with one of another number of pre-trainings than
    ``pretrainings.parquet``, gets the table of the file's rows
    (:func:`~sim2radar.experiment.learnability.pretraining_table`).

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

    pretrainings = _read_pretrainings(folder)
    conds = _conditions(sweep, runs)
    stats = _read_json(folder, "stats")
    stats_source = f"{FILES['stats']}"
    if stats is not None:
        _check_stats(stats, folder / FILES["stats"])
        if not _stats_matches(stats, runs):
            stats = None
            stats_source = (f"computed from {FILES['runs']} ({FILES['stats']} counts other runs: "
                            "written before the latest runs finished)")
        elif pretrainings and _pretrainings_stale(stats, pretrainings):
            profile = _statistics_doc(sweep, folder)["profile"]
            stats["pretrainings"] = pretraining_table(
                pretrainings, profile.get("learnability_thresholds"), _pretrained(conds))
            stats_source += (f" (pre-training table from {FILES['pretrainings']}: "
                             f"{FILES['stats']} has none or another number of pre-trainings)")
    else:
        stats_source = f"computed from {FILES['runs']} ({FILES['stats']} not written yet)"
    if stats is None:
        try:
            stats = sweep_statistics(_statistics_doc(sweep, folder), runs, pretrainings,
                                     conditions=conds)
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
                     stats_source=stats_source, pretrainings=pretrainings,
                     generation=generation, gap=gap,
                     gap_images=images, progress=progress, warnings=warnings)




# ---------------------------------------------------------------------------------------------
# What the page shows (pure)
# ---------------------------------------------------------------------------------------------
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
    rows = [[run_folder(r, sweep_name) if k == "run_folder" else jsonable(r.get(k))
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
    n_pre = prog.get("total_pretrainings")
    n_pre = int(n_pre) if n_pre is not None else int(sweep.get("n_pretrains") or 0)
    pre_done = max(len(data.pretrainings), int(prog.get("pretrainings_finished") or 0))
    state = ("no run planned" if total == 0 else "complete" if finished >= total
             else "running" if finished else "pre-training" if pre_done < n_pre
             else "running" if pre_done else "not started")
    return {"finished": finished, "total": total, "ok": counts["ok"],
            "pretrainings_finished": pre_done, "pretrainings_total": max(n_pre, pre_done),
            "skipped": counts["skipped"], "failed": counts["failed"],
            "running": [r if isinstance(r, str) else json.dumps(jsonable(r)) for r in running],
            "updated_at": prog.get("updated_at"), "state": state}


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


def _signed(v: Any, digits: int = 1) -> str:
    """A signed number with a typographic minus (``+1.2``, ``−0.8``); ``—`` for none."""
    f = num(v)
    return "—" if f is None else format(f, f"+.{digits}f").replace("-", "\u2212")


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
    ci = "" if num(lo) is None or num(hi) is None else f" [{_signed(lo)}, {_signed(hi)}]"
    return _signed(row.get("mean_diff")) + ci


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
    delta = f"Δ {_signed(row['mean_diff'])} AP"
    lo, hi = (list(row.get("t_ci") or []) + [None, None])[:2]
    if num(lo) is not None and num(hi) is not None:
        delta += f" [{_signed(lo)}, {_signed(hi)}] ({_level(stats)} CI, {n} trials)"
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
             _fmt(num(r.get("baseline_mean"))), _fmt(num(r.get("condition_mean"))),
             _pooled_delta(r), _pooled_mde(r), _p_text(r.get("p")), _fmt(num(r.get("d_z")),
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
            r.get("n_heldout_frames"), r.get("n_real_val_frames"), _fmt(num(r.get("train"))),
            _fmt(num(r.get("heldout"))), _fmt(num(r.get("zero_shot"))),
            _fmt(num(r.get("final_loss")), ".3f"), met, str(r.get("status") or "—"),
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


def _fmt(v: Any, spec: str = ",.1f") -> str:
    """A number for a fact table: integers with thousands separators, floats with ``spec``."""
    if isinstance(v, int) and not isinstance(v, bool):
        return f"{v:,}"
    f = num(v)
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
    return jsonable({"datasets": datasets, "generation": gen})


def _share_cell(v: Any) -> str:
    f = num(v)
    return "—" if f is None else f"{100 * f:.1f} %"


def _gap_artefact_rows(art: Any) -> list[list[str]]:
    """Rows [label, sim, real] of ``gap.json["artefacts"]`` (sim2radar.evaluate.gap
    .artefacts_dict); "—" cells for a report without them (written before they existed)."""
    art = art if isinstance(art, Mapping) else {}
    st = art.get("settings") if isinstance(art.get("settings"), Mapping) else {}
    sides = [a if isinstance(a, Mapping) else {} for a in (art.get("sim"), art.get("real"))]
    far, margin = num(st.get("far_range_m")), num(st.get("below_floor_margin_m"))

    def sidelobe(a: Mapping) -> str:
        share, ctl = num(a.get("sidelobe_share")), num(a.get("sidelobe_control_share"))
        if share is None and ctl is None:
            return "—"
        return f"{_share_cell(share)} / {_share_cell(ctl)}"

    def doppler(a: Mapping) -> str:
        d = a.get("doppler")
        if isinstance(d, Mapping):
            med = num(d.get("abs_median_mps"))
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


def _gap_fidelity_rows(fid: Any) -> list[list[str]]:
    """Rows [label, sim, real] of ``gap.json["fidelity"]`` (sim2radar.evaluate.gap: where the
    points are against the true geometry, the door label boxes); none for a report written
    before it existed."""
    if not isinstance(fid, Mapping):
        return []
    sides = [f if isinstance(f, Mapping) else {} for f in (fid.get("sim"), fid.get("real"))]

    def known(v: Any, text: str) -> str:
        return "not measured (no true geometry)" if v is None else text

    def azimuth(f: Mapping) -> str:
        lo, hi = num(f.get("azimuth_lo_deg")), num(f.get("azimuth_hi_deg"))
        return "—" if lo is None or hi is None else f"{lo:+.0f}° to {hi:+.0f}°"

    def labels(f: Mapping) -> str:
        if f.get("label_recall") is None:
            return "—"
        return (f"{_share_cell(f.get('label_recall'))} / {_share_cell(f.get('label_precision'))}"
                f" (width error {_fmt(f.get('label_width_error_m'), '.2f')} m)")

    return [
        ["points > 1 m behind the first true surface",
         *(known(f.get("behind_share"), _share_cell(f.get("behind_share"))) for f in sides)],
        ["points beyond 0.85 R_max",
         *(known(f.get("beyond_share"), _share_cell(f.get("beyond_share"))) for f in sides)],
        ["points in a door label box (median)",
         *(_fmt(f.get("points_per_label"), ".0f") for f in sides)],
        ["door label boxes without points", *(_share_cell(f.get("labels_empty")) for f in sides)],
        ["azimuth covered (1–99 %)", *(azimuth(f) for f in sides)],
        ["door labels vs true doors: recall / precision", *(labels(f) for f in sides)],
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
            *_gap_fidelity_rows(gap.get("fidelity")),
            ["dataset folder", str(sim.get("root", "—")), str(real.get("root", "—"))]]
    ratio = num(gap.get("points_ratio"))
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
    fid = gap.get("fidelity")
    readings = fid.get("readings") if isinstance(fid, Mapping) else None
    if isinstance(readings, list):
        facts += [["reading", str(r)] for r in readings]
    figures = [{"name": name, "uri": uri} for name, uri in data.gap_images.items()]
    return jsonable({"rows": rows, "facts": facts, "figures": figures})


def _with_datasets(config: Any, sweep: Mapping[str, Any]) -> Any:
    """A detector config as the sweep used it: its ``data.root`` is the config file's
    placeholder (each run reads the sweep's datasets), so it shows the datasets instead."""
    if not isinstance(config, Mapping) or not isinstance(config.get("data"), Mapping):
        return config
    roots = {role: d.get("path") for role, d in (sweep.get("datasets") or {}).items()
             if isinstance(d, Mapping)}
    return {**config, "data": {**config["data"], "root": f"(not used: the sweep's datasets "
                                                         f"{roots})"}}


def _provenance(sweep: Mapping[str, Any] | None) -> dict[str, Any] | None:
    if sweep is None:
        return None
    prov = sweep.get("provenance") or {}
    code = prov.get("code")
    git = prov.get("git")
    return jsonable({
        "created_at": sweep.get("created_at"),
        "settings_fixed_at": sweep.get("settings_fixed_at"),
        "settings_digest": sweep.get("settings_digest"),
        "versions": prov.get("versions") or {},
        "code": code if isinstance(code, Mapping) else ({"code": code} if code else {}),
        "git": git if isinstance(git, str) else (json.dumps(jsonable(git)) if git else None),
        "configs": {k: json.dumps(jsonable(_with_datasets(v, sweep)), indent=1)
                    for k, v in (prov.get("configs") or {}).items()},
        "datasets": {role: {"path": d.get("path"), "key": d.get("key"),
                            "domain": d.get("domain")}
                     for role, d in (sweep.get("datasets") or {}).items()
                     if isinstance(d, Mapping)},
        "profile": json.dumps(jsonable(sweep.get("profile") or {}), indent=1),
        "intensity_match": json.dumps(jsonable(sweep.get("intensity_match")), indent=1)
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
        "metric_label": metric_label(metric),
        "created_at": sweep_doc.get("created_at"),
        "profile": profile.get("name") if isinstance(profile, Mapping) else None,
        "banner": _banner(sweep.sweep),
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
        "runs": _runs_table(sweep.runs, metric, sweep.folder.name),
        "datasets": gen["datasets"],
        "generation": gen["generation"],
        "gap": _gap(sweep),
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
