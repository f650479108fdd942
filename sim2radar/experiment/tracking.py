"""A sweep in MLflow: every fine-tuning run and pre-training of a sweep folder as an MLflow run,
under one parent run per sweep, so a team sees its sweeps in the tracker it already uses.

    tracker = SweepTracker("sqlite:///mlflow.db", "out/sweeps/demo")   # needs the mlflow extra
    tracker.sync()               # what the folder holds and MLflow lacks (call it as runs finish)
    tracker.sync(final=True)     # ... and the sweep's statistics and results; parent run closed

The sweep folder is the source of truth and MLflow its mirror. :meth:`SweepTracker.sync` reads
the folder (``sweep.json``, ``runs.parquet``, ``pretrainings.parquet``, ``stats.json``) and logs
each row MLflow does not have yet, so it runs wherever the folder is (the process running the
flow, or later: ``sim2radar sweep-report FOLDER --mlflow URI``) and never where a run trained
(a Dask worker may not reach the tracker).

Idempotence. Each MLflow run is tagged with the sweep's name (``sim2radar.sweep``), its kind
(``sim2radar.kind``: ``sweep``, ``run`` or ``pretraining``), its content key
(``sim2radar.key``: ``run_key`` or ``pretrain_key``) and a digest of the row's outcome
(``sim2radar.identity``: every field but ``status``, ``sweep`` and ``finished_at``, and whether
it failed). A row whose key is logged with the same identity is skipped: logging a folder twice
adds nothing, and a resumed sweep (its finished runs read back as ``skipped``) logs only its new
runs. A row whose outcome changed (a failed run retried, a ``--force-run``) replaces its MLflow
run (the old one is deleted; MLflow keeps deleted runs until its garbage collection), as does a
run whose logging was cut off (still ``RUNNING``: it is terminated last).

What each run holds (:func:`run_params`, :func:`run_metrics`): params — condition, fraction,
trial, seed, frames, epochs, learning rates (``lr``, ``encoder_lr``), the profile's fields
(``profile.*``), the detector's model, augmentation and optimisation settings (``detector.*``),
the datasets' paths and content keys (``dataset.<role>.*``); metrics — the learning curve per
epoch (``train_loss`` and, from the run folder's ``history.json``, its parts and ``lr``;
``val_ap_3d_r40_iou03``; step = epoch) and the test APs ``runs.parquet`` records (its column
names, step 0); tags — sweep, condition, status, run folder, git commit; artifacts — the row
(``row.json``) and the run folder's small files (``config.json``, ``history.json``,
``check.json``...), checkpoints only when asked. The parent run holds the sweep's settings as
params, its counts and (once ``stats.json`` counts every run) the primary endpoint, the pooled
and per-fraction differences and the cell means as metrics, and the sweep's files (``stats.json``,
``results.md``, ``runs.parquet``...) as artifacts.

A tracker that fails (unreachable, refusing a write) raises :class:`TrackingError`, or with
``on_error="warn"`` says so once and does nothing more: the sweep goes on. MLflow is an optional
extra (``pip install 'sim2radar[mlflow]'``); :func:`require_mlflow` fails without it, naming it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import threading
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

from sim2radar.experiment.dashboard.labels import num
from sim2radar.experiment.documents import DocumentError, SweepDocument
from sim2radar.experiment.folder import SweepFolder
from sim2radar.experiment.stats import stats_count_runs
from sim2radar.fileio import json_text, jsonable

__all__ = [
    "MLFLOW_EXTRA",
    "KINDS",
    "MlflowMissing",
    "SweepSnapshot",
    "SweepTracker",
    "SyncResult",
    "TrackingError",
    "TrackingWarning",
    "read_sweep_folder",
    "require_mlflow",
    "run_metrics",
    "run_name",
    "run_params",
]

#: how to install what logging to MLflow needs
MLFLOW_EXTRA = "pip install 'sim2radar[mlflow]'"
#: MLflow run kinds (tag ``sim2radar.kind``): the sweep's parent run, a fine-tuning run, a
#: pre-training
KINDS = ("sweep", "run", "pretraining")
#: tags identifying a logged row (see the module docstring)
TAG_SWEEP, TAG_KIND, TAG_KEY, TAG_IDENTITY = ("sim2radar.sweep", "sim2radar.kind",
                                              "sim2radar.key", "sim2radar.identity")
#: MLflow's tag naming a run's parent (a nested run), and its git commit tag
TAG_PARENT, TAG_GIT = "mlflow.parentRunId", "mlflow.source.git.commit"
#: a run folder's file larger than this is not logged (a checkpoint is logged only when asked)
MAX_RUN_ARTIFACT_BYTES = 1 << 20
#: a sweep file larger than this is not logged with the parent run (a paper-sized dashboard is
#: ~10 MB, a plan ~1 MB) [bytes]
MAX_SWEEP_ARTIFACT_BYTES = 64 << 20
#: the sweep folder's files the parent run holds (each, or its ``.gz`` copy in a published one)
SWEEP_ARTIFACTS = SweepFolder.DOCUMENTS
#: history.json fields that are not per-epoch metrics (the total loss comes from the row)
_NOT_CURVES = frozenset({"epoch", "total", "val_ap", "seconds", "hook_seconds"})
#: row fields that do not change what a row says (left out of its identity)
_NOT_IDENTITY = frozenset({"status", "sweep", "finished_at"})
#: columns a sweep folder's tables must have to be logged
_RUN_COLUMNS = ("run_key", "condition", "fraction", "trial", "seed", "status", "finished_at")
_PRETRAIN_COLUMNS = ("pretrain_key", "pretrain_id", "sim_role", "seed", "status", "finished_at")


class MlflowMissing(ImportError):
    """MLflow is not installed (the ``mlflow`` extra)."""


class TrackingError(RuntimeError):
    """The MLflow tracker could not be reached or refused a write; the message names the
    tracking URI, what failed and how to log the sweep later."""


class TrackingWarning(UserWarning):
    """Logging to MLflow stopped (``on_error="warn"``); the sweep folder keeps every result."""


def require_mlflow():
    """The ``mlflow`` module.

    Raises
    ------
    MlflowMissing (an ImportError) — MLflow is not installed; the message names the extra.
    """
    try:
        import mlflow
    except ImportError as exc:
        raise MlflowMissing(f"logging to MLflow needs the mlflow extra: {MLFLOW_EXTRA} "
                            f"({exc})") from None
    return mlflow


# ------------------------------------------------------------------------ the sweep folder
@dataclasses.dataclass(frozen=True)
class SweepSnapshot:
    """What of a sweep folder goes to MLflow.

    Attributes
    ----------
    path : Path — the sweep folder.
    name : str — the sweep's name (``sweep.json``'s, else the folder's).
    doc : SweepDocument — ``sweep.json`` (or its ``.gz`` copy).
    runs : list of dict — ``runs.parquet`` rows (empty: no run finished yet).
    pretrainings : list of dict — ``pretrainings.parquet`` rows (empty: none).
    stats : dict or None — ``stats.json`` when it counts exactly the runs of ``runs.parquet``
        (None: not written yet, or written before the latest runs finished).
    """

    path: Path
    name: str
    doc: SweepDocument
    runs: list[dict[str, Any]]
    pretrainings: list[dict[str, Any]]
    stats: dict[str, Any] | None = None


def _read_table(path: Path, columns: Sequence[str], what: str) -> list[dict[str, Any]]:
    import pyarrow.parquet as pq

    if not path.is_file():
        return []
    try:
        table = pq.read_table(path)
    except Exception as exc:  # pyarrow raises ArrowInvalid, OSError... for a damaged file
        raise ValueError(f"{path}: cannot be read as Parquet ({exc}); rerun the sweep to "
                         f"rewrite it") from None
    missing = [c for c in columns if c not in table.column_names]
    if missing:
        raise ValueError(f"{path}: lacks the column(s) {missing} of {what}; is it the "
                         "sweep's own file?")
    return table.to_pylist()


def read_sweep_folder(folder: str | os.PathLike) -> SweepSnapshot:
    """Read what of a sweep folder goes to MLflow (a running, finished or published sweep).

    Raises
    ------
    ValueError — no such folder, no readable ``sweep.json``, a damaged or foreign table, or
    a sweep name MLflow's search cannot quote; the message names the file and the fix.
    """
    path = Path(folder)
    if not path.is_dir():
        raise ValueError(f"{path}: no such sweep folder")
    layout = SweepFolder(path)
    sweep_json = layout.sweep_json
    try:
        doc = layout.read_sweep_document()
    except DocumentError as exc:
        raise ValueError(f"{sweep_json}: {exc.problem}; rerun `sim2radar sweep` with the same "
                         "name to rewrite it") from None
    if doc is None:
        raise ValueError(f"{sweep_json}: not found; a sweep folder holds the sweep.json "
                         "`sim2radar sweep` writes before its first run")
    name = doc.name or path.name
    if not name or not all(c.isalnum() or c in "-_." for c in name):
        raise ValueError(f"{sweep_json}: sweep name {name!r} has characters other than "
                         "letters, digits, '-', '_' and '.'; it names the sweep's MLflow runs")
    runs = _read_table(layout.runs_table, _RUN_COLUMNS, "experiment_runs")
    pretrainings = _read_table(layout.pretrainings_table, _PRETRAIN_COLUMNS,
                               "experiment_pretrain")
    stats = None
    try:
        text = json_text(layout.stats_json)
        stats = None if text is None else json.loads(text)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        stats = None    # the statistics are rebuilt by `sim2radar sweep-report`; not logged
    if not isinstance(stats, dict) or not stats_count_runs(stats, runs):
        stats = None
    return SweepSnapshot(path, name, doc, runs, pretrainings, stats)


# ----------------------------------------------------------------- what a row is in MLflow
def _param_text(value: Any) -> str:
    return value if isinstance(value, str) else json.dumps(jsonable(value))


def _flatten(prefix: str, value: Any, out: dict[str, str]) -> dict[str, str]:
    """``{"a": {"b": 1}}`` -> ``{"prefix.a.b": "1"}``; lists and scalars as JSON text."""
    if isinstance(value, Mapping) and value:
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    else:
        out[prefix] = _param_text(value)
    return out


def _detector_params(config: Any) -> dict[str, str]:
    """The settings of a DetectConfig dump that distinguish runs: model, augmentation and
    optimisation (``detector.<section>.<field>``)."""
    out: dict[str, str] = {}
    if isinstance(config, Mapping):
        for section in ("model", "augmentation", "optimization"):
            if isinstance(config.get(section), Mapping):
                _flatten(f"detector.{section}", config[section], out)
    return out


def _dataset_params(doc: SweepDocument, roles: Iterable[str]) -> dict[str, str]:
    out = {}
    for role in roles:
        ds = doc.datasets.get(role)
        if isinstance(ds, Mapping):
            for field in ("path", "key", "domain", "n_frames"):
                if ds.get(field) is not None:
                    out[f"dataset.{role}.{field}"] = _param_text(ds[field])
    return out


def _held(doc: SweepDocument, fields: Iterable[str]) -> dict[str, Any]:
    """The ``fields`` ``doc`` holds with a value (not null): a field an older sweep.json lacks
    is not logged at its default."""
    return {f: doc.held(f) for f in fields if doc.held(f) is not None}


def _sweep_params(doc: SweepDocument) -> dict[str, str]:
    """Params every run of the sweep shares: its profile (less its description), settings
    digest and metric (so runs compare across sweeps)."""
    profile = {k: v for k, v in doc.profile.items() if k != "description"}
    out = _flatten("profile", profile, {})
    out.update({k: _param_text(v) for k, v in _held(doc, ("settings_digest", "metric")).items()})
    return out


def _configs(doc: SweepDocument) -> Mapping[str, Any]:
    return doc.provenance.get("configs") or {}


def _learning_rates(doc: SweepDocument, condition: str) -> dict[str, Any]:
    """The fine-tuning config of ``condition`` (its encoder learning-rate share applied) and
    its learning rates: ``lr`` (the head's), ``encoder_lr_scale``, ``encoder_lr``."""
    from sim2radar.experiment.profiles import CONDITIONS

    config = _configs(doc).get("finetune")
    known = condition in CONDITIONS
    if isinstance(config, Mapping) and isinstance(config.get("optimization"), Mapping):
        # the recorded dump as the run used it (plan.condition_config's change, on the dump as
        # sweep.json holds it, whichever version of DetectConfig wrote it)
        config = dict(config)
        if known and CONDITIONS[condition].encoder_lr_scale != 1.0:
            config["optimization"] = {**config["optimization"],
                                      "encoder_lr_scale": CONDITIONS[condition].encoder_lr_scale}
        optim = config["optimization"]
        lr, scale = optim.get("lr"), optim.get("encoder_lr_scale", 1.0)
    else:
        lr = doc.profile.get("lr")
        scale = CONDITIONS[condition].encoder_lr_scale if known else None
    out = {"config": config, "lr": lr, "encoder_lr_scale": scale}
    if lr is not None and scale is not None:
        out["encoder_lr"] = float(f"{float(lr) * float(scale):.12g}")
    return out


def run_name(row: Mapping[str, Any]) -> str:
    """A fine-tuning run's readable id (:attr:`~sim2radar.experiment.plan.RunSpec.name`, e.g.
    ``sim-pretrain-f0.25-t3``)."""
    from sim2radar.experiment.plan import RunSpec

    return RunSpec(condition=str(row["condition"]), fraction=float(row["fraction"]),
                   trial=int(row["trial"]), seed=int(row["seed"]),
                   n_real=int(row.get("n_real_frames") or 0), pretrain=None,
                   epochs=int(row.get("epochs") or 0)).name


def run_params(folder: SweepSnapshot, row: Mapping[str, Any], kind: str) -> dict[str, str]:
    """The MLflow params of a ``runs.parquet`` row (``kind="run"``) or a
    ``pretrainings.parquet`` row (``kind="pretraining"``) of ``folder``."""
    from sim2radar.experiment.profiles import CONDITIONS

    doc = folder.doc
    out = _sweep_params(doc)
    if kind == "run":
        cond = str(row["condition"])
        rates = _learning_rates(doc, cond)
        role = CONDITIONS[cond].sim_role if cond in CONDITIONS else None
        out.update(_detector_params(rates.pop("config")))
        out.update(_dataset_params(doc, ["real", *([role] if role else [])]))
        fields = ("condition", "fraction", "trial", "seed", "n_real_frames", "n_sim_frames",
                  "epochs", "pretrain_key")
        out.update({k: _param_text(row.get(k)) for k in fields})
        out.update({k: _param_text(v) for k, v in rates.items()})
        out["sim_role"] = _param_text(role)
    else:
        config = _configs(doc).get("pretrain")
        out.update(_detector_params(config))
        role = str(row["sim_role"])
        out.update(_dataset_params(doc, [role]))
        fields = ("sim_role", "trial", "fraction", "seed", "n_sim_frames", "holdout_split",
                  "n_heldout_frames", "n_real_val_frames", "epochs")
        out.update({k: _param_text(row.get(k)) for k in fields})
        out["conditions"] = ",".join(row.get("conditions") or ())
        optim = config.get("optimization") if isinstance(config, Mapping) else None
        out["lr"] = _param_text(optim.get("lr") if isinstance(optim, Mapping)
                                else doc.profile.get("lr"))
    return out


def _history_file(run_dir: Path | None, epochs: Sequence[int]) -> list[dict[str, Any]]:
    """The run folder's ``history.json`` records, when they are the row's epochs."""
    if run_dir is None or not (run_dir / SweepFolder.HISTORY).is_file():
        return []
    try:
        hist = json.loads((run_dir / SweepFolder.HISTORY).read_text()).get("history") or []
    except (OSError, ValueError, AttributeError):
        return []
    if [int(h.get("epoch", -1)) for h in hist if isinstance(h, dict)] != list(epochs):
        return []     # another attempt's history (or a damaged file): the row is the truth
    return hist


def run_metrics(row: Mapping[str, Any], kind: str, run_dir: Path | None = None,
                ) -> list[tuple[str, float, int]]:
    """The MLflow metrics of a row as ``(key, value, step)``: the learning curve per epoch
    (``train_loss``, ``val_ap_3d_r40_iou03``; with ``run_dir``'s ``history.json`` its loss
    parts ``train_loss_<part>`` and ``lr``), and the row's final figures at step 0 (test APs
    or the pre-training's checks, wall time, steps). Missing and non-finite values are left
    out."""
    epochs = [int(e) for e in row.get("history_epoch") or ()]
    out = [("train_loss", v, e) for e, v in zip(epochs, row.get("history_loss") or (),
                                                strict=False) if num(v) is not None]
    if kind == "run":
        out += [("val_ap_3d_r40_iou03", v, int(e)) for e, v in
                zip(row.get("history_val_epoch") or (), row.get("history_val_ap") or (),
                    strict=False) if num(v) is not None]
    for rec in _history_file(run_dir, epochs):
        for key, v in rec.items():
            if key in _NOT_CURVES or num(v) is None:
                continue
            out.append((key if key == "lr" else f"train_loss_{key}", float(v),
                        int(rec["epoch"])))
    finals = [k for k in row if k.startswith("ap_") or "_ap_" in k]
    finals += ["wall_time_s", "check_s", "steps", "sim_real_ratio"]
    out += [(k, num(row.get(k)), 0) for k in finals if num(row.get(k)) is not None]
    return [(k, float(v), int(s)) for k, v, s in out]


def _identity(row: Mapping[str, Any]) -> str:
    """A digest of what a row says (:data:`_NOT_IDENTITY` left out; ok and skipped alike)."""
    doc = {k: v for k, v in row.items() if k not in _NOT_IDENTITY}
    doc["failed"] = row.get("status") == "failed"
    text = json.dumps(jsonable(doc), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def _ms(iso: Any, minus_s: Any = 0.0) -> int | None:
    try:
        t = datetime.fromisoformat(str(iso))
    except ValueError:
        return None
    if t.tzinfo is None:
        t = t.replace(tzinfo=UTC)
    return int(1000 * (t.timestamp() - (num(minus_s) or 0.0)))


def _run_dir(folder: SweepSnapshot, row: Mapping[str, Any], kind: str) -> Path | None:
    """The row's run folder where it exists: its checkpoint's folder (written relative to the
    sweep's parent folder; a run found finished in the store keeps the folder of the sweep that
    trained it), else ``runs/<key>`` or ``pretrain/<key>``."""
    ckpt = str(row.get("checkpoint") or "")
    key = row["run_key" if kind == "run" else "pretrain_key"]
    for cand in ((folder.path.parent / ckpt).parent if ckpt else None,
                 SweepFolder(folder.path).job_dir("runs" if kind == "run" else "pretrain",
                                                  str(key))):
        if cand is not None and cand.is_dir():
            return cand.resolve()
    return None


def _git_tags(doc: SweepDocument) -> dict[str, str]:
    commit = doc.provenance.get("git")
    if not isinstance(commit, str) or not commit:
        return {}
    return {"sim2radar.git_commit": commit, TAG_GIT: commit.removesuffix("-dirty")}


def _password(uri: str) -> str | None:
    from urllib.parse import urlsplit

    try:
        return urlsplit(uri).password
    except ValueError:
        return None


def _safe_uri(uri: str) -> str:
    """``uri`` without a password (``https://user:secret@host`` -> ``https://user:***@host``)."""
    from urllib.parse import urlsplit, urlunsplit

    secret = _password(uri)
    if not secret:
        return uri
    parts = urlsplit(uri)
    return urlunsplit(parts._replace(netloc=parts.netloc.replace(f":{secret}@", ":***@", 1)))


# ---------------------------------------------------------------------------- the tracker
@dataclasses.dataclass(frozen=True)
class SyncResult:
    """What one :meth:`SweepTracker.sync` did.

    Attributes
    ----------
    experiment_id, parent_run_id : str or None — the MLflow experiment and the sweep's parent
        run (None when tracking failed before them).
    logged : tuple of str — ids of the runs and pre-trainings logged now (replacements
        included).
    replaced : tuple of str — of those, the ones whose earlier MLflow run was deleted (their
        outcome changed, or their logging had been cut off).
    unchanged : int — rows already logged with the same outcome (skipped).
    error : str or None — why tracking stopped (``on_error="warn"``).
    """

    experiment_id: str | None
    parent_run_id: str | None
    logged: tuple[str, ...] = ()
    replaced: tuple[str, ...] = ()
    unchanged: int = 0
    error: str | None = None


@dataclasses.dataclass
class _Logged:
    run_id: str
    identity: str
    status: str
    parent: str | None


class SweepTracker:
    """Mirrors one sweep folder into an MLflow experiment (see the module docstring).

    Parameters
    ----------
    tracking_uri : MLflow tracking URI: ``sqlite:///mlflow.db`` (MLflow's local store; its
        artifacts go to ``./mlruns`` unless ``artifact_location`` says otherwise), ``http(s)://``
        a tracking server, ``databricks``...
    sweep_dir : the sweep folder.
    experiment : MLflow experiment name (default: the sweep's name); created when missing.
    artifact_location : where a newly created experiment keeps its artifacts (None: the
        tracker's default).
    checkpoints : also log each run's final checkpoint (``last.pt``).
    on_error : ``"raise"`` — a tracker failure raises :class:`TrackingError` (and a folder
        that cannot be read ValueError); ``"warn"`` — the first failure of any kind is reported
        once through ``warn`` and the tracker does nothing more (the sweep goes on; the
        folder can be logged later).
    warn : ``warn(message)`` for ``on_error="warn"`` (default: :func:`warnings.warn` with
        :class:`TrackingWarning`).

    Raises
    ------
    MlflowMissing — MLflow is not installed (raised here, before anything else runs).
    """

    def __init__(self, tracking_uri: str, sweep_dir: str | os.PathLike, *,
                 experiment: str | None = None, artifact_location: str | None = None,
                 checkpoints: bool = False, on_error: Literal["raise", "warn"] = "raise",
                 warn: Callable[[str], None] | None = None) -> None:
        if on_error not in ("raise", "warn"):
            raise ValueError(f"on_error must be 'raise' or 'warn', got {on_error!r}")
        require_mlflow()
        self.tracking_uri, self.sweep_dir = str(tracking_uri), Path(sweep_dir)
        self.experiment, self.artifact_location = experiment, artifact_location
        self.checkpoints, self.on_error = checkpoints, on_error
        self._warn = warn or (lambda msg: warnings.warn(msg, TrackingWarning, stacklevel=3))
        self.error: str | None = None
        self._lock = threading.Lock()
        self._client = None
        self._experiment_id: str | None = None
        self._parent: str | None = None
        self._parent_state: dict[str, Any] = {}
        self._logged: dict[tuple[str, str], _Logged] = {}

    @property
    def uri(self) -> str:
        """The tracking URI without a password (for messages)."""
        return _safe_uri(self.tracking_uri)

    def sync(self, *, final: bool = False) -> SyncResult:
        """Log what the sweep folder holds and MLflow lacks: each new (or changed) run and
        pre-training, the parent run's counts and, when ``stats.json`` counts every run, its
        statistics; with ``final`` also the sweep's files and the parent's end (FINISHED when
        every planned run finished, FAILED when a run or pre-training failed, KILLED when runs
        are missing), else the parent stays RUNNING.

        Raises
        ------
        TrackingError, ValueError — with ``on_error="raise"`` (see the class).
        """
        with self._lock:
            if self.error is not None:
                return SyncResult(self._experiment_id, self._parent, error=self.error)
            try:
                folder = read_sweep_folder(self.sweep_dir)
                return self._sync(folder, final)
            except Exception as exc:
                if self.on_error == "raise":
                    raise
                # a failure of any kind must not stop the sweep: its folder keeps every result
                self.error = str(exc) if isinstance(exc, TrackingError | ValueError) else (
                    f"{type(exc).__name__}: {exc}")
                self._warn(f"MLflow logging stopped, the sweep goes on: {self.error}" + (
                    "" if isinstance(exc, TrackingError) else
                    f"; the sweep folder keeps every result: {self._fix}"))
                return SyncResult(self._experiment_id, self._parent, error=self.error)

    @property
    def _fix(self) -> str:
        return f"log it later with `sim2radar sweep-report {self.sweep_dir} --mlflow {self.uri}`"

    # --- the MLflow side
    def _call(self, what: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """``fn(*args, **kwargs)``, a tracker failure raised as :class:`TrackingError`."""
        from mlflow.exceptions import MlflowException

        try:
            return fn(*args, **kwargs)
        except (MlflowException, OSError) as exc:
            text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            secret = _password(self.tracking_uri)
            if secret:      # MLflow's message repeats the URI it was given
                text = text.replace(secret, "***")
            raise TrackingError(
                f"MLflow at {self.uri}: {what} failed ({type(exc).__name__}: {text[:500]}); "
                f"the sweep folder keeps every result: {self._fix}") from exc

    def _connect(self, folder: SweepSnapshot) -> None:
        """The client, the experiment, and what of this sweep it already holds."""
        from mlflow import MlflowClient
        from mlflow.entities import ViewType

        if self._client is not None:
            return
        client = self._call("opening the tracking store", MlflowClient,
                            tracking_uri=self.tracking_uri)
        name = self.experiment or folder.name
        exp = self._call(f"looking up experiment {name!r}", client.get_experiment_by_name, name)
        if exp is None:
            try:
                exp_id = self._call(f"creating experiment {name!r}", client.create_experiment,
                                    name, artifact_location=self.artifact_location,
                                    tags={TAG_SWEEP: folder.name})
            except TrackingError:   # created meanwhile by another process?
                exp = self._call(f"looking up experiment {name!r}",
                                 client.get_experiment_by_name, name)
                if exp is None:
                    raise
                exp_id = exp.experiment_id
        elif exp.lifecycle_stage != "active":
            raise TrackingError(f"MLflow at {self.uri}: experiment {name!r} is deleted; "
                                f"restore it (`mlflow experiments restore --experiment-id "
                                f"{exp.experiment_id}`) or log to another experiment name "
                                "(--mlflow-experiment)")
        else:
            exp_id = exp.experiment_id
        runs, token = [], None
        while True:
            page = self._call("searching the sweep's runs", client.search_runs, [exp_id],
                              filter_string=f"tags.`{TAG_SWEEP}` = '{folder.name}'",
                              run_view_type=ViewType.ACTIVE_ONLY, max_results=1000,
                              page_token=token)
            runs.extend(page)
            token = page.token
            if not token:
                break
        self._client, self._experiment_id = client, exp_id
        parents = sorted((r for r in runs if r.data.tags.get(TAG_KIND) == "sweep"),
                         key=lambda r: r.info.start_time or 0)
        if parents:
            self._parent = parents[0].info.run_id
            self._parent_state = {"metrics": dict(parents[0].data.metrics),
                                  "status": parents[0].info.status,
                                  "artifacts": parents[0].data.tags.get("sim2radar.artifacts")}
        for r in runs:
            tags = r.data.tags
            kind, key = tags.get(TAG_KIND), tags.get(TAG_KEY)
            if kind not in KINDS[1:] or not key:
                continue
            entry = _Logged(r.info.run_id, tags.get(TAG_IDENTITY, ""), r.info.status,
                            tags.get(TAG_PARENT))
            old = self._logged.get((kind, key))
            if old is None or (old.status == "RUNNING" and entry.status != "RUNNING"):
                if old is not None:
                    self._delete(old.run_id)
                self._logged[(kind, key)] = entry
            else:
                self._delete(entry.run_id)       # a duplicate (two loggers at once)

    def _delete(self, run_id: str) -> None:
        self._call(f"deleting the superseded run {run_id}", self._client.delete_run, run_id)

    def _sync(self, folder: SweepSnapshot, final: bool) -> SyncResult:
        self._connect(folder)
        if self._parent is None:
            self._parent = self._create_parent(folder)
        logged, replaced, unchanged = [], [], 0
        rows = [("pretraining", r) for r in folder.pretrainings] + [("run", r)
                                                                    for r in folder.runs]
        for kind, row in rows:
            key = str(row["run_key" if kind == "run" else "pretrain_key"])
            ident = _identity(row)
            old = self._logged.get((kind, key))
            if old is not None and old.identity == ident and old.status != "RUNNING":
                if old.parent != self._parent:    # the parent was deleted and made anew
                    self._call("re-parenting a run", self._client.set_tag, old.run_id,
                               TAG_PARENT, self._parent)
                    old.parent = self._parent
                unchanged += 1
                continue
            name = run_name(row) if kind == "run" else str(row["pretrain_id"])
            if old is not None:
                self._delete(old.run_id)
                replaced.append(name)
            self._logged[(kind, key)] = self._log_row(folder, kind, key, ident, name, row)
            logged.append(name)
        self._update_parent(folder, final)
        return SyncResult(self._experiment_id, self._parent, tuple(logged), tuple(replaced),
                          unchanged)

    def _create_parent(self, folder: SweepSnapshot) -> str:
        from mlflow.entities import Param

        doc = folder.doc
        tags = {TAG_SWEEP: folder.name, TAG_KIND: "sweep",
                "sim2radar.sweep_dir": str(folder.path.resolve()),
                "sim2radar.real_domain": doc.real_domain,
                **_git_tags(doc)}
        description = doc.profile.get("description")
        if description:
            tags["mlflow.note.content"] = str(description)[:5000]
        run = self._call("creating the sweep's parent run", self._client.create_run,
                         self._experiment_id, run_name=f"sweep {folder.name}", tags=tags,
                         start_time=_ms(doc.created_at))
        params = _sweep_params(doc)
        params.update({k: _param_text(v) for k, v in _held(doc, (
            "conditions", "fractions", "trials", "n_runs", "n_pretrains", "real_domain",
            "real_is_proxy", "settings_fixed_at")).items()})
        params.update(_dataset_params(doc, list(doc.datasets)))
        versions = doc.provenance.get("versions") or {}
        params.update(_flatten("version", versions, {}) if versions else {})
        self._call("logging the sweep's settings", self._client.log_batch, run.info.run_id,
                   params=[Param(k, v) for k, v in params.items()])
        self._parent_state = {"metrics": {}, "status": "RUNNING", "artifacts": None}
        return run.info.run_id

    def _log_row(self, folder: SweepSnapshot, kind: str, key: str, ident: str, name: str,
                 row: Mapping[str, Any]) -> _Logged:
        from mlflow.entities import Metric, Param

        client, doc = self._client, folder.doc
        failed = row.get("status") == "failed"
        run_dir = _run_dir(folder, row, kind)
        tags = {TAG_SWEEP: folder.name, TAG_KIND: kind, TAG_KEY: key, TAG_IDENTITY: ident,
                TAG_PARENT: self._parent, "sim2radar.status": str(row.get("status")),
                "sim2radar.finished_at": str(row.get("finished_at") or ""),
                "sim2radar.sweep_dir": str(folder.path.resolve()), **_git_tags(doc)}
        if kind == "run":
            tags["sim2radar.condition"] = str(row["condition"])
            if row.get("pretrain_key"):
                tags["sim2radar.pretrain_key"] = str(row["pretrain_key"])
        else:
            tags["sim2radar.conditions"] = ",".join(row.get("conditions") or ())
        if run_dir is not None:
            tags["sim2radar.run_dir"] = str(run_dir)
        if failed:
            tags["sim2radar.error"] = str(row.get("error") or "")[:2000]
        end = _ms(row.get("finished_at"))
        start = _ms(row.get("finished_at"), row.get("wall_time_s"))
        run = self._call(f"creating the MLflow run of {name}", client.create_run,
                         self._experiment_id, run_name=name, tags=tags, start_time=start)
        run_id = run.info.run_id
        stamp = end if end is not None else int(datetime.now(UTC).timestamp() * 1000)
        metrics = [Metric(k, v, stamp, s) for k, v, s in run_metrics(row, kind, run_dir)]
        params = [Param(k, v) for k, v in run_params(folder, row, kind).items()]
        self._call(f"logging {name}", client.log_batch, run_id, metrics=metrics, params=params)
        self._call(f"logging {name}'s row", client.log_dict, run_id, jsonable(dict(row)),
                   "row.json")
        for path in self._run_files(run_dir):
            self._call(f"logging {name}'s {path.name}", client.log_artifact, run_id, str(path),
                       "checkpoints" if path.suffix == ".pt" else None)
        status = "FAILED" if failed else "FINISHED"
        self._call(f"closing the MLflow run of {name}", client.set_terminated, run_id, status,
                   end)
        return _Logged(run_id, ident, status, self._parent)

    def _run_files(self, run_dir: Path | None) -> list[Path]:
        """A run folder's small files (``config.json``, ``history.json``, ``check.json``...),
        and ``last.pt`` with ``checkpoints``."""
        if run_dir is None:
            return []
        files = sorted(p for p in run_dir.iterdir() if p.is_file() and p.suffix != ".pt"
                       and not p.name.startswith(".")
                       and p.stat().st_size <= MAX_RUN_ARTIFACT_BYTES)
        if self.checkpoints and (run_dir / SweepFolder.LAST_CHECKPOINT).is_file():
            files.append(run_dir / SweepFolder.LAST_CHECKPOINT)
        return files

    def _update_parent(self, folder: SweepSnapshot, final: bool) -> None:
        from mlflow.entities import Metric

        client, parent, state = self._client, self._parent, self._parent_state
        metrics = _parent_metrics(folder)
        changed = {k: v for k, v in metrics.items() if state["metrics"].get(k) != v}
        if changed:
            stamp = int(datetime.now(UTC).timestamp() * 1000)
            step = len(folder.runs)
            self._call("logging the sweep's metrics", client.log_batch, parent,
                       metrics=[Metric(k, v, stamp, step) for k, v in changed.items()])
            state["metrics"].update(changed)
        if final:
            files = _sweep_files(folder.path)
            digest = hashlib.sha256()
            for f in files:
                digest.update(f.name.encode() + b"\0" + f.read_bytes())
            if files and digest.hexdigest()[:20] != state.get("artifacts"):
                for f in files:
                    self._call(f"logging {f.name}", client.log_artifact, parent, str(f))
                state["artifacts"] = digest.hexdigest()[:20]
                self._call("tagging the sweep's files", client.set_tag, parent,
                           "sim2radar.artifacts", state["artifacts"])
        status = _sweep_status(folder) if final else "RUNNING"
        if status != state.get("status"):
            if status == "RUNNING":
                self._call("reopening the sweep's run", client.update_run, parent, "RUNNING")
            else:
                self._call("closing the sweep's run", client.set_terminated, parent, status)
            state["status"] = status


def _sweep_files(folder: Path) -> list[Path]:
    """The sweep's own files the parent run holds (:data:`SWEEP_ARTIFACTS`)."""
    out = []
    for name in SWEEP_ARTIFACTS:
        for cand in (folder / name, folder / f"{name}.gz"):
            if cand.is_file() and cand.stat().st_size <= MAX_SWEEP_ARTIFACT_BYTES:
                out.append(cand)
                break
    return out


def _sweep_status(folder: SweepSnapshot) -> str:
    """FAILED when a run or pre-training failed, KILLED when planned runs are missing,
    FINISHED otherwise."""
    rows = [*folder.runs, *folder.pretrainings]
    if any(r.get("status") == "failed" for r in rows):
        return "FAILED"
    planned = folder.doc.held("n_runs")
    if isinstance(planned, int) and len({r["run_key"] for r in folder.runs}) < planned:
        return "KILLED"
    return "FINISHED"


def _frac(f: Any) -> str:
    return f"f{float(f):g}"


def _parent_metrics(folder: SweepSnapshot) -> dict[str, float]:
    """The parent run's metrics: counts, and from fresh statistics the primary endpoint
    (``primary.*``), the other pooled differences (``pooled.<condition>.*``), the per-fraction
    differences (``delta.<condition>.f<fraction>``, ``p_holm...``) and the cell means
    (``mean.<condition>.f<fraction>``)."""
    runs, pre = folder.runs, folder.pretrainings
    out: dict[str, float | None] = {
        "runs_finished": sum(r.get("status") != "failed" for r in runs),
        "runs_failed": sum(r.get("status") == "failed" for r in runs),
        "runs_planned": num(folder.doc.held("n_runs")),
        "pretrainings_finished": sum(r.get("status") != "failed" for r in pre),
        "pretrainings_failed": sum(r.get("status") == "failed" for r in pre),
    }
    stats = folder.stats or {}
    for x in stats.get("pooled") or ():
        prefix = "primary" if x.get("primary") else f"pooled.{x.get('condition')}"
        ci = x.get("t_ci") or (None, None)
        out.update({f"{prefix}.mean_diff": x.get("mean_diff"), f"{prefix}.ci_low": ci[0],
                    f"{prefix}.ci_high": ci[1], f"{prefix}.p": x.get("p"),
                    f"{prefix}.mde": x.get("mde"), f"{prefix}.n_pairs": x.get("n_pairs")})
    for x in stats.get("comparisons") or ():
        cell = f"{x.get('condition')}.{_frac(x.get('fraction'))}"
        out[f"delta.{cell}"] = x.get("mean_diff")
        out[f"p_holm.{cell}"] = x.get("p_holm")
    for c in stats.get("cells") or ():
        out[f"mean.{c.get('condition')}.{_frac(c.get('fraction'))}"] = c.get("mean")
    return {k: float(v) for k, v in ((k, num(v)) for k, v in out.items()) if v is not None}
