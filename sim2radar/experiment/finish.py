"""Finishing a sweep: the statistics, report and dashboard of its runs' rows.

    summary = finish_sweep(plan, rows, pretrainings)   # at the end of the flow
    write_results(folder, doc, rows, pretrainings)     # sim2radar sweep-report: a published one

Writes the sweep folder's ``stats.json``, ``results.md`` and ``dashboard.html``
(:class:`~sim2radar.experiment.folder.SweepFolder`); the other phases are
:mod:`sim2radar.experiment.prepare` and :func:`sim2radar.experiment.cost.sweep_cost`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sim2radar.experiment.documents import SweepDocument
from sim2radar.experiment.folder import SweepFolder
from sim2radar.experiment.plan import SweepPlan
from sim2radar.vocab import STATUSES

__all__ = ["finish_sweep", "write_results"]


def write_results(sweep_dir: str | os.PathLike, doc: SweepDocument,
                  rows: Sequence[Mapping[str, Any]],
                  pretrainings: Sequence[Mapping[str, Any]] = ()) -> dict[str, Any]:
    """Write a sweep folder's ``stats.json``, ``results.md`` and ``dashboard.html`` from its
    ``sweep.json`` document and rows (what :func:`finish_sweep` does at the end of a sweep, and
    ``sim2radar sweep-report`` does for a published one). Returns ``stats``, ``markdown`` and
    the paths ``results_md``, ``dashboard``.

    ``doc``: the :class:`~sim2radar.experiment.documents.SweepDocument` (the plan's, or
    :meth:`~.folder.SweepFolder.read_sweep_document`'s).
    """
    from sim2radar.experiment.dashboard import write_dashboard
    from sim2radar.experiment.report import results_markdown
    from sim2radar.experiment.stats import sweep_statistics
    from sim2radar.fileio import atomic_write, write_json

    sweep_dir = Path(sweep_dir)
    folder = SweepFolder(sweep_dir)
    stats = sweep_statistics(doc, rows, pretrainings)
    md = results_markdown(stats, rows, title=f"Sweep {doc.name}",
                          real_domain_label=doc.real_domain, proxy=doc.real_is_proxy,
                          settings={"profile": doc.profile.get("name"),
                                    "digest": doc.settings_digest,
                                    "fixed_at": doc.settings_fixed_at},
                          preregistration=doc.preregistration)
    write_json(folder.stats_json, stats)
    atomic_write(folder.results_md, md.encode())
    dashboard = write_dashboard(sweep_dir, folder.dashboard_html)
    return {"stats": stats, "markdown": md, "results_md": str(folder.results_md),
            "dashboard": str(dashboard)}


def finish_sweep(plan: SweepPlan, rows: Sequence[Mapping[str, Any]],
                 pretrainings: Sequence[Mapping[str, Any]] = ()) -> dict[str, Any]:
    """Statistics, report and dashboard of a sweep's ``experiment_runs`` rows and its
    pre-trainings' ``experiment_pretrain`` rows; writes ``stats.json``, ``results.md`` and
    ``dashboard.html`` into the sweep folder (:func:`write_results`).

    Returns ``counts`` (runs by status), ``metric``, ``stats``, ``markdown``, ``table_rows``
    (for a Prefect table artifact) and the paths ``sweep_dir``, ``results_md``, ``dashboard``.
    """
    from sim2radar.experiment.report import results_table_rows

    sweep_dir, rows = Path(plan.context.sweep_dir), list(rows)
    res = write_results(sweep_dir, plan.sweep, rows, pretrainings)
    counts = {k: sum(r["status"] == k for r in rows) for k in STATUSES}
    return {"name": plan.name, "sweep_dir": str(sweep_dir), "counts": counts,
            "metric": plan.metric, "stats": res["stats"], "markdown": res["markdown"],
            "table_rows": results_table_rows(res["stats"]), "results_md": res["results_md"],
            "dashboard": res["dashboard"]}
