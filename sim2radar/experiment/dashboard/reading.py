"""Reading a sweep folder (explicit I/O: the folder is given).

    load_sweep(folder) -> SweepData          read the sweep folder

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

``sweep.json`` and ``progress.json`` are read as their types
(:class:`~sim2radar.experiment.documents.SweepDocument`, :class:`~sim2radar.experiment.
documents.SweepProgress`) by :class:`~sim2radar.experiment.folder.SweepFolder`; the other JSON
files are open-ended and checked here for the parts the page reads.

``runs.parquet`` and ``pretrainings.parquet`` are read with pyarrow and checked against the
columns the page reads (:data:`RUNS_COLUMNS`, :data:`PRETRAIN_COLUMNS`): the library does not
import the store (``sim2radar.storage``), whose layer is above it. Of the gap report's PNGs
only those of figures whose numbers ``gap.json`` lacks are read (:func:`~.gap.png_fallbacks`:
a report written before them); the page draws the others from the numbers.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sim2radar.experiment.dashboard.gap import png_fallbacks
from sim2radar.experiment.dashboard.labels import num
from sim2radar.experiment.documents import DocumentError, SweepDocument, SweepProgress
from sim2radar.experiment.folder import SweepFolder
from sim2radar.experiment.learnability import pretraining_table
from sim2radar.experiment.profiles import BASELINE, CONDITIONS
from sim2radar.experiment.rows import RUN_COLUMNS
from sim2radar.experiment.stats import (
    AP_METRICS,
    DEFAULT_METRIC,
    stats_count_runs,
    sweep_statistics,
)
from sim2radar.fileio import json_text

__all__ = [
    "FILES",
    "PRETRAIN_COLUMNS",
    "RUNS_COLUMNS",
    "SweepData",
    "SweepFolderError",
    "conditions_of",
    "load_sweep",
]

#: files of a sweep folder the dashboard reads, by role
FILES = {"runs": SweepFolder.RUNS, "sweep": SweepFolder.SWEEP, "stats": SweepFolder.STATS,
         "pretrainings": SweepFolder.PRETRAININGS, "generation": SweepFolder.GENERATION,
         "gap": SweepFolder.GAP_REPORT, "progress": SweepFolder.PROGRESS}
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
    sweep : SweepDocument or None — ``sweep.json``.
    stats : dict or None — the statistics
        (:func:`~sim2radar.experiment.stats.sweep_statistics`' structure): ``stats.json`` when
        it matches the runs, else recomputed from ``runs`` and ``pretrainings``.
    stats_source : str — where ``stats`` came from, one line for the page.
    pretrainings : list of dict — ``experiment_pretrain`` rows of ``pretrainings.parquet``, in
        file order (empty: no such file).
    generation : dict or None — ``generation.json``.
    gap : dict or None — ``gap/gap.json``.
    gap_images : dict[str, str] — figure name -> ``data:image/png;base64,...`` of the PNGs
        that ``gap.json`` names, that exist and whose figure it holds no numbers for
        (:func:`~.gap.png_fallbacks`).
    progress : SweepProgress or None — ``progress.json``.
    warnings : list of str — what was missing or ignored, one line each.
    """

    folder: Path
    runs: list[dict[str, Any]]
    sweep: SweepDocument | None = None
    stats: dict[str, Any] | None = None
    stats_source: str = ""
    pretrainings: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    generation: dict[str, Any] | None = None
    gap: dict[str, Any] | None = None
    gap_images: dict[str, str] = dataclasses.field(default_factory=dict)
    progress: SweepProgress | None = None
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


def _read_document(folder: Path, role: str) -> SweepDocument | SweepProgress | None:
    """``sweep.json`` (``role`` ``sweep``) or ``progress.json`` (``progress``) as its type;
    None where the file does not exist."""
    layout = SweepFolder(folder)
    try:
        return layout.read_sweep_document() if role == "sweep" else layout.read_progress()
    except DocumentError as exc:
        raise SweepFolderError(f"{exc.path}: {exc.problem}; {_FIXES[role]}") from None


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


#: the ``runs.parquet`` columns the dashboard checks, with the kind of value each holds: every
#: column of the ``experiment_runs`` row (declared once, :data:`~sim2radar.experiment.rows.
#: RUN_COLUMNS`; the store's schema derives from it too, and the sweep flow validates the table
#: before it writes the file). The library reads the file without importing the store's layer,
#: so it checks here what it reads. Other columns are kept and not shown.
RUNS_COLUMNS: dict[str, str] = {c.name: c.kind for c in RUN_COLUMNS}
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


def conditions_of(sweep: SweepDocument | None, runs: Sequence[Mapping[str, Any]]) -> list[str]:
    """Planned conditions (sweep.json) then any others found in the runs, baseline first."""
    planned = list(sweep.conditions) if sweep is not None else []
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


def _statistics_doc(sweep: SweepDocument | None, folder: Path) -> SweepDocument:
    """``sweep.json`` as :func:`~sim2radar.experiment.stats.sweep_statistics` reads it: its
    ``metric`` checked (default :data:`DEFAULT_METRIC`), its ``profile``'s ``fractions``,
    ``primary_fractions`` and ``learnability_thresholds`` (condition -> held-out sim AP [%])
    and its own ``fractions`` finite numbers; a document of the folder's name with the default
    metric and no profile without ``sweep.json``.

    Raises
    ------
    SweepFolderError — a field of another kind, naming ``sweep.json`` and the fix.
    """
    path = folder / FILES["sweep"]
    doc = sweep if sweep is not None else SweepDocument(name=folder.name)
    metric = doc.metric or DEFAULT_METRIC
    if metric not in AP_METRICS:
        raise SweepFolderError(f"{path}: field 'metric' is {metric!r}, not one of "
                               f"{list(AP_METRICS)}; {_FIXES['sweep']}")
    profile = dict(doc.profile)
    written = {k: doc.held(k) for k in ("fractions", "primary_fractions")}
    for where, holder in (("", written), ("profile.", profile)):
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
    return doc.model_copy(update={"metric": metric, "profile": profile})


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
    sweep = _read_document(folder, "sweep")
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
    conds = conditions_of(sweep, runs)
    stats = _read_json(folder, "stats")
    stats_source = f"{FILES['stats']}"
    if stats is not None:
        _check_stats(stats, folder / FILES["stats"])
        if not stats_count_runs(stats, runs):
            stats = None
            stats_source = (f"computed from {FILES['runs']} ({FILES['stats']} counts other runs: "
                            "written before the latest runs finished)")
        elif pretrainings and _pretrainings_stale(stats, pretrainings):
            profile = _statistics_doc(sweep, folder).profile
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
    progress = _read_document(folder, "progress")

    gap = _read_json(folder, "gap")
    images: dict[str, str] = {}
    if gap is not None:
        figures = gap.get("figures") or {}
        if not isinstance(figures, dict):
            raise SweepFolderError(f"{folder / FILES['gap']}: field 'figures' is not an object; "
                                   f"{_FIXES['gap']}")
        gap_dir = (folder / FILES["gap"]).parent
        fallbacks = png_fallbacks(gap)
        for name, file in figures.items():
            if name not in fallbacks:
                continue  # drawn from gap.json's numbers
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
