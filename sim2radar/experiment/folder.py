"""The sweep folder's layout, in one place: :class:`SweepFolder` owns every path of a sweep.

    folder = SweepFolder("out/sweeps/demo")
    folder.sweep_json, folder.runs_table, folder.run_dir(key), folder.pretrain_dir(key)
    folder.read_sweep_document()     # sweep.json as a SweepDocument, None before it is prepared
    folder.write_sweep_document(doc), folder.update_sweep(packing=...)
    folder.read_progress(), folder.write_progress(SweepProgress(...))   # progress.json

What lives there (``<out>/<name>/``)::

    sweep.json            the sweep's document: profile, conditions, datasets, provenance,
                          settings and their digest, precision and packing decisions
    plan.json             the prepared plan the flow runs (run specs, configs, matches)
    runs.parquet          one experiment_runs row per finished fine-tuning run
    pretrainings.parquet  one experiment_pretrain row per finished pre-training (its check)
    progress.json         runs and pre-trainings finished / failed, updated as they finish
    stats.json            paired statistics; results.md the Table-1-style report
    dashboard.html        the offline dashboard
    preregistration.md    the study's pre-registration, when the profile declares one
    generation.json       the datasets' generation summaries (``sim2radar demo``)
    gap/gap.json          the sim-real gap report (and its figures)
    pretrain/<key>/       a pre-training's checkpoints and check.json
    runs/<key>/           a fine-tuning run's checkpoints and history.json
    quarantine/<kind>/<key>.<stamp>/   folders moved aside by --force-run

Every module that reads or writes a sweep folder goes through this class; a test checks that
no other module spells these file names.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sim2radar.experiment.documents import SweepDocument, SweepProgress

__all__ = ["SweepFolder"]


@dataclasses.dataclass(frozen=True)
class SweepFolder:
    """The paths of one sweep folder (nothing is read or created by making one)."""

    root: Path

    #: file names, relative to the folder
    SWEEP = "sweep.json"
    PLAN = "plan.json"
    RUNS = "runs.parquet"
    PRETRAININGS = "pretrainings.parquet"
    PROGRESS = "progress.json"
    STATS = "stats.json"
    RESULTS = "results.md"
    DASHBOARD = "dashboard.html"
    PREREGISTRATION = "preregistration.md"
    GENERATION = "generation.json"
    GAP = "gap"
    GAP_REPORT = "gap/gap.json"
    #: training folders by kind (``pretrain``, ``runs``) and what they hold
    LAST_CHECKPOINT = "last.pt"
    HISTORY = "history.json"
    CHECK = "check.json"
    DONE = "done.json"
    #: the raw files a published study keeps (small; checkpoints stay behind)
    PUBLISHED = (SWEEP, PLAN, RUNS, PRETRAININGS, STATS, PROGRESS, PREREGISTRATION)
    #: the small documents an experiment tracker gets as the sweep's artifacts
    DOCUMENTS = (SWEEP, PLAN, STATS, RESULTS, PROGRESS, PREREGISTRATION, RUNS, PRETRAININGS,
                 DASHBOARD)

    def __init__(self, root: str | os.PathLike) -> None:
        object.__setattr__(self, "root", Path(root))

    def __fspath__(self) -> str:
        return os.fspath(self.root)

    def __truediv__(self, other: str) -> Path:
        return self.root / other

    # --- files ---------------------------------------------------------------------------
    @property
    def sweep_json(self) -> Path:
        return self.root / self.SWEEP

    @property
    def plan_json(self) -> Path:
        return self.root / self.PLAN

    @property
    def runs_table(self) -> Path:
        return self.root / self.RUNS

    @property
    def pretrainings_table(self) -> Path:
        return self.root / self.PRETRAININGS

    @property
    def progress_json(self) -> Path:
        return self.root / self.PROGRESS

    @property
    def stats_json(self) -> Path:
        return self.root / self.STATS

    @property
    def results_md(self) -> Path:
        return self.root / self.RESULTS

    @property
    def dashboard_html(self) -> Path:
        return self.root / self.DASHBOARD

    @property
    def preregistration_md(self) -> Path:
        return self.root / self.PREREGISTRATION

    @property
    def generation_json(self) -> Path:
        return self.root / self.GENERATION

    @property
    def gap_dir(self) -> Path:
        return self.root / self.GAP

    @property
    def gap_json(self) -> Path:
        return self.root / self.GAP_REPORT

    # --- training folders ----------------------------------------------------------------
    def job_dir(self, kind: str, key: str) -> Path:
        """``pretrain/<key>`` or ``runs/<key>``."""
        if kind not in ("pretrain", "runs"):
            raise ValueError(f"kind must be 'pretrain' or 'runs', got {kind!r}")
        return self.root / kind / key

    def pretrain_dir(self, key: str) -> Path:
        return self.job_dir("pretrain", key)

    def run_dir(self, key: str) -> Path:
        return self.job_dir("runs", key)

    def quarantine_dir(self, kind: str, key: str, stamp: str) -> Path:
        """Where ``--force-run`` moves a job's folder: ``quarantine/<kind>/<key>.<stamp>``."""
        return self.root / "quarantine" / kind / f"{key}.{stamp}"

    # --- documents -------------------------------------------------------------------------
    #: what a damaged document's message tells its reader to do
    SWEEP_FIX = ("delete it (and the sweep folder's runs if they are not wanted) or choose a new "
                 "sweep name")
    PROGRESS_FIX = "delete it: the sweep writes it again when its next job finishes"

    def _read_document(self, path: Path, kind: type, fix: str) -> Any:
        """``path``'s document as ``kind`` (or its ``.gz`` copy's: a published sweep), None
        when neither exists; :class:`~.documents.DocumentError` when it cannot be read as
        one."""
        from sim2radar.experiment.documents import DocumentError, parse_document
        from sim2radar.fileio import json_text

        try:
            text = json_text(path)
            if text is None:
                return None
            value = json.loads(text)
        except json.JSONDecodeError as exc:
            raise DocumentError(path, f"not valid JSON ({exc.msg} at line {exc.lineno}, column "
                                f"{exc.colno})", fix) from None
        except (OSError, UnicodeDecodeError) as exc:
            raise DocumentError(path, f"cannot be read ({exc})", fix) from None
        return parse_document(kind, value, path, fix)

    def read_sweep_document(self) -> SweepDocument | None:
        """sweep.json (or the ``sweep.json.gz`` a published sweep keeps) as its
        :class:`~.documents.SweepDocument`, or None when it does not exist yet (a sweep not
        prepared).

        Raises
        ------
        DocumentError (a ValueError) — it exists but is not the sweep's document: not JSON,
            not an object, a field of another type, or settings deleted (or nulled) from a file
            that had them; its ``problem`` says which in one line.
        """
        from sim2radar.experiment.documents import SweepDocument

        return self._read_document(self.sweep_json, SweepDocument, self.SWEEP_FIX)

    def write_sweep_document(self, doc: SweepDocument) -> Path:
        """Write sweep.json (atomically; the bytes :func:`~sim2radar.fileio.write_json` writes
        for the fields ``doc`` holds, in their order)."""
        from sim2radar.fileio import write_json

        return write_json(self.sweep_json, doc.model_dump(mode="json"))

    def update_sweep(self, **fields: Any) -> Path:
        """Add or replace top-level fields of sweep.json (written atomically; a new field goes
        last, a replaced one stays in its place), checked as a
        :class:`~.documents.SweepDocument`.

        Raises
        ------
        FileNotFoundError — no sweep.json: the sweep was not prepared.
        DocumentError — sweep.json, or it with ``fields``, is not the sweep's document.
        """
        from sim2radar.experiment.documents import SweepDocument, parse_document

        doc = self.read_sweep_document()
        if doc is None:
            raise FileNotFoundError(f"{self.sweep_json}: not found; prepare the sweep before "
                                    "recording anything in it")
        return self.write_sweep_document(parse_document(
            SweepDocument, {**doc.model_dump(mode="json"), **fields}, self.sweep_json,
            self.SWEEP_FIX))

    def read_progress(self) -> SweepProgress | None:
        """progress.json as its :class:`~.documents.SweepProgress`, or None when the sweep has
        not written one (no job finished yet, or a sweep from before the file).

        Raises
        ------
        DocumentError — it exists but is not the sweep's progress.
        """
        from sim2radar.experiment.documents import SweepProgress

        return self._read_document(self.progress_json, SweepProgress, self.PROGRESS_FIX)

    def write_progress(self, progress: SweepProgress) -> Path:
        """Write progress.json (atomically, the fields ``progress`` holds in their order: a
        live dashboard polling it never reads half a file)."""
        from sim2radar.fileio import write_json

        return write_json(self.progress_json, progress.model_dump(mode="json"))
