"""``sim2radar dashboard``: the sweep dashboard, as a file or served live, or two sweeps
compared.

    sim2radar dashboard out/sweeps/demo --out demo.html       # one self-contained page
    sim2radar dashboard demo --out demo.html                   # a name under --root
    sim2radar dashboard demo --serve                           # live on 127.0.0.1:8765
    sim2radar dashboard demo demo2 --out cmp.html              # two sweeps compared

The page works offline (Plotly and the data inline). ``--serve`` shows it on a loopback
address and the page refreshes itself as the sweep's runs finish; Ctrl-C stops it. Each run
has its own view (click its row; served, also ``/run/<run id>``). With two sweeps the page
compares them (per shared condition and fraction: both mean APs with their intervals, the
difference of their Δ to the baseline; the settings that differ; what only one ran); it is
written with ``--out`` only (``--serve`` shows one sweep).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from sim2radar.cli._app import app, fail

__all__ = ["dashboard", "resolve_sweep"]

#: default port of ``--serve``
DEFAULT_PORT = 8765


def resolve_sweep(sweep: str, root: Path) -> Path:
    """The sweep folder: ``sweep`` itself when it is a folder, else ``root / sweep``.

    Raises
    ------
    ValueError — neither exists (the message names both and the fix).
    """
    path = Path(sweep)
    if path.is_dir():
        return path
    is_name = path.name == sweep and not path.is_absolute()
    if is_name and (root / sweep).is_dir():
        return root / sweep
    tried = f"{sweep} and {root / sweep}" if is_name else sweep
    raise ValueError(f"{tried}: no such sweep folder; give the sweep's folder or its name "
                     "under --root")


@app.command()
def dashboard(
    sweep: Annotated[list[str], typer.Argument(
        help="Sweep folder, or a sweep name under --root; two to compare them (A B).")],
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Write the self-contained HTML page here.")] = None,
    serve: Annotated[bool, typer.Option(
        "--serve", help="Serve a live page on 127.0.0.1 until Ctrl-C.")] = False,
    port: Annotated[int, typer.Option(
        "--port", min=0, max=65535, help="Port of --serve (0: any free port).")] = DEFAULT_PORT,
    root: Annotated[Path, typer.Option(
        "--root", help="Folder of sweeps, for a sweep given by name.")] = Path("out/sweeps"),
    poll: Annotated[float, typer.Option(
        "--poll", min=0.2, help="Seconds between the live page's refreshes.")] = 3.0,
) -> None:
    """Sweep dashboard: AP vs real data, differences with intervals, learning curves, runs
    (each with its own view), datasets, sim-real gap, provenance. Offline HTML (--out) or
    live (--serve). With two sweeps: a page comparing them (--out)."""
    from sim2radar.experiment.dashboard import serve_dashboard, write_comparison, write_dashboard

    if len(sweep) > 2:
        raise fail(f"{len(sweep)} sweeps given: give one sweep, or two (A B) to compare them")
    if len(sweep) == 2 and serve:
        raise fail("--serve shows one sweep live; to compare two sweeps write the page: "
                    f"sim2radar dashboard {sweep[0]} {sweep[1]} --out cmp.html")
    if out is None and not serve:
        raise fail("nothing to do: give --out FILE.html, --serve, or both"
                    if len(sweep) == 1 else "give --out FILE.html for the comparison page")
    try:
        if len(sweep) == 2:
            a, b = (resolve_sweep(s, root) for s in sweep)
            try:
                typer.echo(str(write_comparison(a, b, out)))
            except OSError as exc:
                raise fail(f"{out}: cannot be written ({exc.strerror or exc}); choose "
                            "another --out") from None
            return
        folder = resolve_sweep(sweep[0], root)
        if out is not None:
            try:
                typer.echo(str(write_dashboard(folder, out)))
            except OSError as exc:
                raise fail(f"{out}: cannot be written ({exc.strerror or exc}); choose "
                            "another --out") from None
        if serve:
            try:
                server = serve_dashboard(folder, port=port, poll_s=poll)
            except OSError as exc:  # the port is taken
                raise fail(f"port {port}: {exc.strerror or exc}; choose another --port "
                            "(0: any free port)") from None
    except ValueError as exc:  # SweepFolderError is a ValueError
        raise fail(str(exc)) from None
    if not serve:
        return
    typer.echo(f"serving {folder} at {server.url} (Ctrl-C stops)")
    try:
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
    typer.echo("stopped")
