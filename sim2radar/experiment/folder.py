"""The sweep folder's layout, in one place: :class:`SweepFolder` owns every path of a sweep.

    folder = SweepFolder("out/sweeps/demo")
    folder.sweep_json, folder.runs_table, folder.run_dir(key), folder.pretrain_dir(key)
    folder.read_sweep()          # sweep.json as a dict, or None before the sweep is prepared

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
from typing import Any

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
    def read_sweep(self) -> Any:
        """sweep.json's JSON value (the sweep's document, a dict, unless the file was edited),
        or None when it does not exist yet.

        Raises
        ------
        ValueError — it exists but cannot be read as JSON (the message names the file and fix).
        """
        try:
            return json.loads(self.sweep_json.read_text()) if self.sweep_json.is_file() else None
        except (OSError, ValueError) as exc:
            raise ValueError(f"{self.sweep_json}: unreadable ({exc}); delete it (and the sweep "
                             "folder's runs if they are not wanted) or choose a new sweep "
                             "name") from None

    def update_sweep(self, **fields: Any) -> Path:
        """Add or replace top-level fields of sweep.json (written atomically)."""
        from sim2radar.fileio import write_json

        doc = self.read_sweep()
        return write_json(self.sweep_json, {**(doc if isinstance(doc, dict) else {}), **fields})
