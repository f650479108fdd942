"""The sweep dashboard: one self-contained HTML page per sweep folder, a live view of it, and a
page comparing two sweeps.

    load_sweep(folder) -> SweepData          read the sweep folder (explicit I/O, path given)
    dashboard_data(sweep) -> dict            what the page shows, JSON-able (pure)
    render_html(data, live=False) -> str     the page: Plotly's JS and the data inline (pure)
    write_dashboard(folder, out_path)        the three above, written atomically
    serve_dashboard(folder, port=0)          the live page on 127.0.0.1: ``/``, ``/data.json``
                                             and ``/run/<run id>``
    compare_data(a, b) -> dict               two sweeps compared, JSON-able (pure)
    render_compare_html(data) -> str         the comparison page (pure)
    write_comparison(a, b, out_path)         both loaded, compared and written atomically

Modules:

- :mod:`~.reading` — reading the sweep folder (its files are listed there), checked against the
  columns the page reads.
- :mod:`~.data` — the page's JSON document: statistics, tables, progress, provenance; pure
  Python.
- :mod:`~.runs` — the runs table and each run's own view (its settings, learning curve, final
  APs, its pre-training's check, its folder).
- :mod:`~.gap` — the sim–real gap section: ``gap.json``'s tables, and which figures are drawn
  from its numbers (:mod:`~.gap_plots`, Plotly) or shown as the report's PNG.
- :mod:`~.compare` — two sweeps side by side: both mean APs per shared cell, the difference of
  their Δs to the baseline with Welch's interval, the settings that differ, what only one ran.
- :mod:`~.figures` — the Plotly figures (AP, difference to the baseline, learning curves, the
  pre-trainings' checks and loss curves, a run's curve);
  :mod:`~.labels` — names, colours and numbers as the page shows them.
- :mod:`~.page` — the pages: the Jinja2 templates ``dashboard.html.j2`` and
  ``compare.html.j2`` with their scripts (``dashboard.js``, ``compare.js``, both on
  ``common.js``) and ``dashboard.css`` (package data in ``sim2radar/experiment/page/``, read
  through :mod:`importlib.resources`), with Plotly's bundle and the data inlined.
- :mod:`~.server` — the live page's HTTP server on a loopback address.

The page works offline: Plotly's bundle and the data are inline (the sim–real gap figures as
Plotly figures of ``gap.json``'s numbers; a PNG, as a ``data:`` URI, only for a figure an older
report holds no numbers for, and the page says so), and a Content-Security-Policy in the page
forbids loading anything else. The live page polls ``data.json`` every few seconds and
re-renders in place (``Plotly.react``, rebuilt tables), so runs appear as the sweep finishes
them, without a reload.

Plot traces carry ``meta = {"role": ..., "condition": ...}``; the count rule the browser test
checks: the AP figure has exactly one ``"mean"`` trace and one ``"trials"`` trace per condition
of :func:`dashboard_data`'s ``conditions`` (empty where a condition has no finished run yet).
The difference figure adds, per non-baseline condition, an ``"mde"`` trace (the minimum
detectable effect per fraction) and one ``"paper-delta"`` trace (the paper's Table 1 Δ); its
error bars are the simultaneous interval the Holm verdict agrees with.

The page leads with the pre-registered primary endpoint (the Δ pooled over the low-data
fractions, one test) above the per-fraction comparisons (secondary, Holm-adjusted), and shows
what every pre-training learned before fine-tuning (held-out sim AP, zero-shot real AP, the
pre-registered thresholds, the loss curves) from ``pretrainings.parquet``.

Every number leads back to its run: the runs table has each run's folder relative to the sweep
(``run_folder``), the trial points' hover names it, and the page filters and groups the runs
by condition, fraction and trial and downloads the rows it shows as CSV or JSON (built in the
page: no request). Clicking a run opens its own view, as an experiment tracker's run page: its
settings, its learning curve (loss and validation AP per epoch, the final test AP), its final
APs beside its cell's mean, its paired Δ to the baseline of the same trial, the check of the
pre-training it loaded (by ``pretrain_key``) and its folder; the address names it
(``#run=<run key>``; live also ``/run/<run key>``), so a run can be linked to.

``sim2radar dashboard A B --out cmp.html`` compares two sweeps (:func:`compare_data`): the
comparison page is rendered by the same machinery from its own template, as a file (the live
server shows one sweep).
"""

from sim2radar.experiment.dashboard.compare import compare_data
from sim2radar.experiment.dashboard.data import dashboard_data
from sim2radar.experiment.dashboard.page import (
    POLL_S,
    render_compare_html,
    render_html,
    write_comparison,
    write_dashboard,
)
from sim2radar.experiment.dashboard.reading import FILES, SweepData, SweepFolderError, load_sweep
from sim2radar.experiment.dashboard.runs import run_folder, run_views
from sim2radar.experiment.dashboard.server import (
    LOOPBACK_HOST_NAMES,
    DashboardServer,
    allowed_host,
    serve_dashboard,
)

__all__ = [
    "FILES",
    "LOOPBACK_HOST_NAMES",
    "POLL_S",
    "DashboardServer",
    "SweepData",
    "SweepFolderError",
    "allowed_host",
    "compare_data",
    "dashboard_data",
    "load_sweep",
    "render_compare_html",
    "render_html",
    "run_folder",
    "run_views",
    "serve_dashboard",
    "write_comparison",
    "write_dashboard",
]
