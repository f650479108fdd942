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
