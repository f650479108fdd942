"""``sim2radar models check CONFIG``: try every model a reconstruction config names, before a run.

    sim2radar models check configs/reconstruct/production.yaml

One line per stage's backend — ``ok`` with what ran (a tiny input through each ``.onnx``, the VLM
server's model list), or what is wrong and how to fix it (:mod:`sim2radar.reconstruct.check`).
Exit status: 0 when every backend is ok, 1 otherwise, 2 for a config file that cannot be read.
"""

from __future__ import annotations

from pathlib import Path

import typer

from sim2radar.cli._app import app

models_app = typer.Typer(
    rich_markup_mode=None, help="The model files and VLM server a reconstruction config names.",
    no_args_is_help=True)
app.add_typer(models_app, name="models")


@models_app.command("check")
def check_cmd(
    config: Path = typer.Argument(..., help="Reconstruction config YAML "
                                            "(configs/reconstruct/*.yaml format)."),
) -> None:
    """Load every configured model file, run one tiny input through it, ask the VLM server which
    models it serves; one line per backend. Exit 0 when all are ok, 1 otherwise, 2 for a bad
    config file."""
    from sim2radar.reconstruct import ReconstructionConfig
    from sim2radar.reconstruct.check import check_models

    try:
        results = check_models(ReconstructionConfig.from_yaml(config))
    except (FileNotFoundError, ValueError) as exc:
        why = " ".join(str(exc).split())
        typer.secho(f"error: {why if str(config) in why else f'{config}: {why}'}", fg="red",
                    err=True)
        raise typer.Exit(2) from None
    for result in results:
        typer.secho(result.line(), fg=None if result.ok else "red")
    if not all(r.ok for r in results):
        raise typer.Exit(1)
