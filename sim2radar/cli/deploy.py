"""``sim2radar deploy``: register the project's Prefect deployments from the installed package.

    sim2radar deploy --list                           # what there is
    sim2radar deploy --all                            # every deployment, schedules off
    sim2radar deploy nightly-generate --schedule      # one, with its nightly schedule on
    sim2radar deploy --all --home /srv/sim2radar --pool gpu
    sim2radar deploy --prefect-yaml prefect.yaml      # the same as a file for `prefect deploy`

The deployments go to the Prefect server the CLI reports to (``PREFECT_API_URL``, the active
Prefect profile, or the managed local server of ``PREFECT_HOME``, started if needed). Their
entrypoints are module paths, so a process worker started in any folder runs the installed
package: ``prefect worker start --pool sim2radar-cpu``. Runs execute in ``--home`` (default
``$SIM2RADAR_HOME``, else the folder you deploy from), made absolute when you deploy; the
parameters' relative paths (``out/store``) are relative to it.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer

from sim2radar.cli._app import app, fail

__all__ = ["deploy"]


def _home(home: Path | None) -> str:
    """``--home``, else ``$SIM2RADAR_HOME``, else the current folder; absolute, and a folder."""
    chosen = home or Path(os.environ.get("SIM2RADAR_HOME") or Path.cwd())
    from sim2radar.flows.deployments import home_problem

    path = chosen.expanduser().resolve()
    source = "--home" if home else ("SIM2RADAR_HOME" if os.environ.get("SIM2RADAR_HOME")
                                    else "the current folder")
    if not path.is_dir():
        raise fail(f"{source} {chosen}: no such folder; create it or give another --home")
    if problem := home_problem(path):
        raise fail(f"{source}: {problem}")
    return str(path)


@app.command()
def deploy(
    names: Annotated[list[str] | None, typer.Argument(
        help="Deployments to register (name or flow/name); none: give --all.")] = None,
    all_: Annotated[bool, typer.Option("--all", help="Register every deployment.")] = False,
    list_: Annotated[bool, typer.Option("--list", help="List the deployments and exit.")] = False,
    home: Annotated[Path | None, typer.Option(
        "--home", help="Folder runs execute in [default: $SIM2RADAR_HOME, else the current "
                       "folder].")] = None,
    pool: Annotated[str, typer.Option("--pool", help="Work pool (a process pool is created "
                                                     "when missing).")] = "sim2radar-cpu",
    queue: Annotated[str, typer.Option("--queue", help="Work queue of the pool.")] = "default",
    schedule: Annotated[bool, typer.Option(
        "--schedule", help="Turn the deployments' schedules on (default: registered off).")
    ] = False,
    prefect_yaml: Annotated[Path | None, typer.Option(
        "--prefect-yaml", help="Write the deployments as a prefect.yaml for `prefect deploy` "
                               "instead of registering them.")] = None,
) -> None:
    """Register sim2radar's Prefect deployments (nightly radar, generate, reference, captures,
    sweep) from the installed package, with module entrypoints, a work pool, the folder runs
    execute in, and schedules off unless --schedule."""
    from sim2radar.flows.deployments import Target, definitions, select

    entries = definitions()
    if list_:
        from sim2radar.flows.deployments import flow_of

        for entry in entries:
            flow = flow_of(entry).name
            crons = ", ".join(s["cron"] for s in entry.get("schedules") or []) or "no schedule"
            typer.echo(f"{flow + '/' + entry['name']:50s} {crons}")
        return
    if prefect_yaml is not None:
        from sim2radar.flows.deployments import write_prefect_yaml

        target = Target(home=str(home) if home else "{{ $SIM2RADAR_HOME }}", pool=pool,
                        queue=queue, schedule=schedule)
        try:
            typer.echo(str(write_prefect_yaml(prefect_yaml, target)))
        except OSError as exc:
            raise fail(f"{prefect_yaml}: cannot be written ({exc.strerror or exc})") from None
        return
    if not names and not all_:
        raise fail("nothing to deploy: name deployments or give --all (--list lists them)")
    if names and all_:
        raise fail("give deployment names or --all, not both")
    try:
        chosen = select(entries, list(names or []))
    except KeyError as exc:
        raise fail(exc.args[0]) from None
    target = Target(home=_home(home), pool=pool, queue=queue, schedule=schedule)

    from sim2radar.cli.server import use_managed_server

    use_managed_server()
    from sim2radar.flows.deployments import apply, ensure_pool

    try:
        if ensure_pool(pool):
            typer.echo(f"created the process work pool {pool}")
        registered = apply(chosen, target)
    except Exception as exc:  # noqa: BLE001 - the API's errors, shown as one line
        raise fail(f"registering the deployments failed: {exc}", code=1) from None
    for name in registered:
        typer.echo(f"deployed {name}")
    state = "on" if schedule else "off (turn on with --schedule or in the UI)"
    typer.echo(f"{len(registered)} deployment(s) on pool {pool}, running in {target.home}; "
               f"schedules {state}.\nStart a worker: prefect worker start --pool {pool}")
