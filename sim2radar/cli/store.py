"""``sim2radar store verify STORE [--repair]``: find the artifacts of a store that do not read.

    sim2radar store verify out/store            # list what does not verify (exit 1 if any)
    sim2radar store verify out/store --repair   # move them into out/store/quarantine/

Every published artifact of every stage and every manifest row file is read in full (footer,
row groups, every page, the recorded schema's stage). A run does the footer check itself on
every cache lookup and heals what fails (:mod:`sim2radar.storage.store`); ``verify`` also finds damage a
run would only meet when it reads the file, and files no run currently asks for. ``--repair``
moves each file that fails into the store's ``quarantine/`` (nothing is deleted) so that the
next run that needs it recomputes it. Exit status: 0 when every file verifies (or every file
that did not was moved aside), 1 when some did not and ``--repair`` was not given, 2 when the
store cannot be opened.
"""

from __future__ import annotations

import typer

from sim2radar.cli._app import app

store_app = typer.Typer(
    rich_markup_mode=None, help="Check and heal an artifact store.", no_args_is_help=True)
app.add_typer(store_app, name="store")


@store_app.command("verify")
def verify_cmd(
    store: str = typer.Argument(..., help="Artifact store: folder or fsspec URI."),
    repair: bool = typer.Option(False, "--repair",
                                help="Move every file that does not verify into the store's "
                                     "quarantine/, so the next run recomputes it."),
) -> None:
    """Read every artifact and manifest row of STORE in full; list the files that do not read.
    Exit 0 when all verify (or were moved aside with --repair), 1 otherwise, 2 for a store
    that cannot be opened."""
    from pathlib import Path

    from sim2radar.storage import ArtifactStore

    if "://" not in store and not Path(store).is_dir():
        typer.secho(f"error: {store}: no such store folder; pass the folder given to "
                    "--out / --store", fg="red", err=True)
        raise typer.Exit(2)
    try:
        st = ArtifactStore(store)
        bad = st.verify_all(repair=repair)
    except (OSError, ValueError) as exc:
        typer.secho(f"error: {store}: {' '.join(str(exc).split())}", fg="red", err=True)
        raise typer.Exit(2) from None
    for row in bad:
        moved = f" -> moved to {row['moved_to']}" if row.get("moved_to") else ""
        typer.echo(f"{row['path']}: {row['problem']}{moved}")
    if not bad:
        typer.echo(f"{st.root}: every artifact and manifest row verifies")
        return
    if repair:
        typer.echo(f"{len(bad)} file(s) moved into {st.root}/quarantine; the next run "
                   "recomputes them")
        return
    typer.echo(f"{len(bad)} file(s) do not verify; `sim2radar store verify {store} --repair` "
               "moves them aside so the next run recomputes them")
    raise typer.Exit(1)
