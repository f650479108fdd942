"""``sim2radar import``: a radar dataset in the format it ships in (KITTI-style ``.bin`` +
KITTI labels + calib, ``.pcd``, ``.npy``) -> the OpenPCDet custom layout a sweep reads
(:mod:`sim2radar.datasets.importers`)."""

from __future__ import annotations

from pathlib import Path

import typer

from sim2radar.cli._app import app, exit_unless_writable

__all__ = ["import_cmd"]


def _ints(text: str | None, option: str) -> tuple[int, ...] | None:
    if not text:
        return None
    try:
        return tuple(int(v) for v in text.split(","))
    except ValueError:
        typer.secho(f"error: {option}: expected comma-separated column numbers, got {text!r}",
                    fg="red", err=True)
        raise typer.Exit(2) from None


@app.command("import")
def import_cmd(
    source: Path = typer.Argument(..., help="The dataset folder: points in velodyne/, points/ "
                                  "or radar/ (or the folder itself), labels in label_2/ or "
                                  "labels/, KITTI calibration in calib/, optional ImageSets/."),
    out: Path = typer.Option(..., "--out", "-o", help="Folder of the OpenPCDet custom layout "
                             "to write (a sweep's real dataset)."),
    fmt: str | None = typer.Option(None, "--format", help="bin | pcd | npy [the suffix found]."),
    point_dims: int | None = typer.Option(None, "--point-dims", min=3, max=64,
                                          help="float32 values per .bin row, required for "
                                          ".bin (KITTI lidar 4, View-of-Delft radar 7)."),
    columns: str | None = typer.Option(None, "--columns", help="Columns of .bin/.npy rows to "
                                       "keep, x y z first, e.g. 0,1,2,3 or 0,1,2,3,5 "
                                       "[first four]."),
    fields: str | None = typer.Option(None, "--fields", help="PCD fields to keep, x y z "
                                      "first [x,y,z,intensity when present]."),
    classes: str = typer.Option("door", "--classes", help="The detector's class names "
                                "(comma-separated); labels match them without case."),
    drop_other_classes: bool = typer.Option(False, "--drop-other-classes",
                                            help="Drop labels of other classes (counted in "
                                            "dataset.json) instead of refusing them."),
    domain: str = typer.Option("measured", "--domain", help="What the data is, for "
                               "dataset.json (measured, or a description)."),
    seed: int = typer.Option(0, help="Seed of the split when the source has no ImageSets."),
) -> None:
    """Import a radar dataset (KITTI-style .bin + labels + calib, .pcd or .npy) into the
    OpenPCDet custom layout, every label file checked before anything is written."""
    from sim2radar.datasets.importers import FORMATS, ImportSettings, import_dataset
    from sim2radar.datasets.openpcdet import DatasetError

    if fmt is not None and fmt not in FORMATS:
        typer.secho(f"error: --format must be one of {sorted(FORMATS)}, got {fmt!r}",
                    fg="red", err=True)
        raise typer.Exit(2)
    exit_unless_writable(str(out), "--out")
    settings = ImportSettings(
        fmt=fmt, point_dims=point_dims, columns=_ints(columns, "--columns"),
        fields=tuple(f.strip() for f in fields.split(",")) if fields else None,
        classes=tuple(c.strip() for c in classes.split(",") if c.strip()),
        drop_other_classes=drop_other_classes, domain=domain, seed=seed)
    try:
        doc = import_dataset(source, out, settings)
    except DatasetError as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None
    dropped = ", ".join(f"{k} {v}" for k, v in doc["labels_dropped"].items()) or "none"
    typer.echo(f"imported {doc['frames']} frames ({doc['points']['num_point_features']} point "
               f"features, {doc['labels']} labels of {doc['classes']}; dropped: {dropped}) "
               f"into {out}; splits {doc['splits']}")
    for note in doc["notes"]:
        typer.secho(f"note: {note}", fg="yellow")
