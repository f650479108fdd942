"""The sweep dashboard: one self-contained HTML page per sweep folder, and a live view of it.

    load_sweep(folder) -> SweepData          read the sweep folder (explicit I/O, path given)
    dashboard_data(sweep) -> dict            what the page shows, JSON-able (pure)
    render_html(data, live=False) -> str     the page: Plotly's JS and the data inline (pure)
    write_dashboard(folder, out_path)        the three above, written atomically
    serve_dashboard(folder, port=0)          the live page on 127.0.0.1: ``/`` and ``/data.json``

Modules:

- :mod:`~.data` — reading the sweep folder (its files are listed there), the runs table, the
  statistics and the page's JSON document; pure Python.
- :mod:`~.figures` — the Plotly figures (AP, difference to the baseline, learning curves, the
  pre-trainings' checks and loss curves);
  :mod:`~.labels` — names, colours and numbers as the page shows them.
- :mod:`~.page` — the page: the Jinja2 template ``dashboard.html.j2`` and the static
  ``dashboard.js`` and ``dashboard.css`` (package data in ``sim2radar/experiment/page/``, read
  through :mod:`importlib.resources`), with Plotly's bundle and the data inlined.
- :mod:`~.server` — the live page's HTTP server on a loopback address.

The page works offline: Plotly's bundle, the data and the sim–real gap PNGs (as ``data:`` URIs)
are inline, and a Content-Security-Policy in the page forbids loading anything else. The live
page polls ``data.json`` every few seconds and re-renders in place (``Plotly.react``, rebuilt
tables), so runs appear as the sweep finishes them, without a reload.

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
page: no request).
"""

from sim2radar.experiment.dashboard.data import (
    FILES,
    SweepData,
    SweepFolderError,
    dashboard_data,
    load_sweep,
    run_folder,
)
from sim2radar.experiment.dashboard.page import POLL_S, render_html, write_dashboard
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
    "dashboard_data",
    "load_sweep",
    "render_html",
    "run_folder",
    "serve_dashboard",
    "write_dashboard",
]
