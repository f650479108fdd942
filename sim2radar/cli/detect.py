"""``sim2radar train`` / ``sim2radar evaluate`` / ``sim2radar detect-demo-data`` commands."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, NoReturn

import typer

from sim2radar.cli._app import app


@app.command()
def train(
    config: Annotated[Path, typer.Argument(help="Detector YAML (configs/detect/*.yaml).")],
    out: Annotated[Path, typer.Option(help="Run folder for checkpoints and history.")] = Path(
        "runs/pointpillars"
    ),
    data: Annotated[Path | None, typer.Option(help="Dataset folder (overrides data.root).")] = None,
    pretrained_encoder: Annotated[
        Path | None, typer.Option(help="Checkpoint whose encoder initialises the model.")
    ] = None,
    epochs: Annotated[int | None, typer.Option(help="Override optimization.epochs.")] = None,
    seed: Annotated[int | None, typer.Option(help="Override the config's seed.")] = None,
    device: Annotated[str | None, typer.Option(help="cpu, cuda, cuda:1 ... (default: auto).")] = None,
    resume: Annotated[bool, typer.Option(help="Continue from OUT/last.pt.")] = False,
    evaluate_split: Annotated[
        str | None, typer.Option("--evaluate", help="After training, report AP on this split.")
    ] = None,
) -> None:
    """Train PointPillars from a config (from scratch, or from a transferred encoder)."""
    from sim2radar.detect.config import load_config
    from sim2radar.detect.train import evaluate_checkpoint
    from sim2radar.detect.train import train as run_train

    try:
        cfg = load_config(config)
    except (FileNotFoundError, ValueError) as exc:
        raise typer.BadParameter(str(exc), param_hint="CONFIG") from exc
    try:  # a malformed dataset, a wrong checkpoint, a resume mismatch: the message says which
        res = run_train(cfg, out_dir=out, init_encoder_from=pretrained_encoder, seed=seed,
                        data_dir=data, epochs=epochs, resume=resume, device=device)
    except (FileNotFoundError, ValueError) as exc:
        _exit_bad_input(exc)
    last = res.history[-1] if res.history else {}
    typer.echo(f"trained {res.epochs} epochs ({res.steps} steps) in {res.seconds:.1f} s; "
               f"final loss {last.get('total', float('nan')):.4f}; checkpoint {res.checkpoint}")
    if evaluate_split:
        try:
            ap = evaluate_checkpoint(res.checkpoint, data_dir=data, split=evaluate_split,
                                     device=device)
        except (FileNotFoundError, ValueError) as exc:
            _exit_bad_input(exc)
        typer.echo(json.dumps(ap, indent=1))


def _exit_bad_input(exc: Exception) -> NoReturn:
    """One line naming the file and the fix (the library's message), exit status 2."""
    typer.secho(f"error: {exc}", fg="red", err=True)
    raise typer.Exit(2) from None


@app.command()
def evaluate(
    checkpoint: Annotated[Path, typer.Argument(help="A checkpoint written by `sim2radar train`.")],
    data: Annotated[Path | None, typer.Option(help="Dataset folder (default: the run's).")] = None,
    split: Annotated[str, typer.Option(help="ImageSets split to evaluate.")] = "test",
    device: Annotated[str | None, typer.Option(help="cpu, cuda ... (default: auto).")] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="Also write the figures here.")] = None,
) -> None:
    """KITTI-protocol 3D / BEV AP (R11, R40; IoU 0.3 and 0.5) of a checkpoint on a split."""
    from sim2radar.detect.train import evaluate_checkpoint

    try:
        res = evaluate_checkpoint(checkpoint, data_dir=data, split=split, device=device)
    except (FileNotFoundError, ValueError) as exc:
        _exit_bad_input(exc)
    for key, value in res.items():
        typer.echo(f"{key:14s} {value:8.2f}")
    if json_out is not None:
        json_out.write_text(json.dumps(res, indent=1))


@app.command("detect-demo-data")
def detect_demo_data(
    out: Annotated[Path, typer.Argument(help="Folder to write (OpenPCDet custom layout).")],
    n_train: int = 32,
    n_val: int = 8,
    n_test: int = 16,
    seed: int = 0,
) -> None:
    """Write a small synthetic door dataset (corridor walls + doors) for smoke runs."""
    from sim2radar.datasets.synthetic import write_synthetic_dataset

    ds = write_synthetic_dataset(out, n_train, n_val, n_test, seed=seed)
    typer.echo(f"wrote {ds}")
