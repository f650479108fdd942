"""The shared Typer application that every command module registers on."""

import typer

app = typer.Typer(
    name="sim2radar",
    help="sim2radar: RGB -> material-labelled 3D scene -> simulated mmWave radar point clouds.",
    no_args_is_help=True,
    add_completion=False,
)


@app.callback()
def _root() -> None:
    """sim2radar: RGB -> material-labelled 3D scene -> simulated mmWave radar point clouds."""


def exit_unless_writable(store: str, option: str = "--out") -> None:
    """Before any work: exit with status 2 and one line naming the path and the fix when the
    local store ``store`` cannot be written (:func:`storage.check_writable`; remote URIs are not
    probed)."""
    from storage import check_writable

    try:
        check_writable(store)
    except (ValueError, PermissionError) as exc:
        typer.secho(f"error: {option}: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None
