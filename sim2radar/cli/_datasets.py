"""What the dataset-making commands (``generate``, ``generate --captures``, ``reference``,
``demo``) share: the progress bar, the model-server preflight, and printing and finishing a
run's summary."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import typer

from sim2radar.cli._app import console as _console

__all__ = ["finish_generate", "preflight", "print_generate_summary", "progress_columns"]


def progress_columns():
    """The progress bar's columns of the dataset-making commands."""
    from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn

    return [TextColumn("[bold]generate"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
            TextColumn("{task.description}")]


def preflight(reconstruction) -> None:
    """A misconfigured VLM server stops the run before any work (ValueError, one line); an
    unreachable one is a warning (the run's retries and ``on_error`` handle it)."""
    from sim2radar.reconstruct.check import preflight_servers

    warning = preflight_servers(reconstruction)
    if warning:
        typer.secho(f"warning: {warning}", fg="yellow", err=True)


def _fmt(v: float, spec: str = ".1f") -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


#: help of every run command's ``--allow-failures``
ALLOW_FAILURES_HELP = ("Exit with status 0 even when some work failed (it is recorded in the "
                       "manifest, and the Prefect run still ends Failed).")


def exit_status(summary: dict[str, Any], *, allow_failures: bool = False,
                strict: bool = False, unit: str = "worlds") -> int:
    """The exit status of a run command, matching the Prefect run's state: 1 when any of its
    work failed (the flow ended Failed) unless ``allow_failures``; 1 under ``strict`` also when
    a material fell back; else 0. Says why on stderr when it is 1."""
    failed = int(summary["counts"].get("failed", 0))
    total = sum(int(n) for n in summary["counts"].values())
    fallbacks = fallback_count(summary)
    if failed and not allow_failures:
        typer.secho(f"{failed} of {total} {unit} failed (recorded in the manifest; the others finished): "
                    "exit status 1 (--allow-failures exits 0)", fg="red", err=True)
        return 1
    if strict and (failed or fallbacks):
        typer.secho(f"--strict: {failed} {unit} failed, {fallbacks} material(s) fell back: "
                    "exit status 1", fg="red", err=True)
        return 1
    return 0


def finish_generate(summary: dict[str, Any], json_out: Path | None, strict: bool,
                    allow_failures: bool = False) -> None:
    """The end of a generate-style command: print the summary, write it as JSON if asked, and
    exit with :func:`exit_status` (1 when a world or frame failed, unless ``allow_failures``;
    under ``strict`` also when a material fell back)."""
    print_generate_summary(summary)
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(summary, indent=1, default=str))
    code = exit_status(summary, allow_failures=allow_failures, strict=strict,
                       unit=summary.get("unit", "worlds"))
    if summary.get("prefect_server_went_away"):
        from sim2radar.cli._app import exit_now

        exit_now(code)
    if code:
        raise typer.Exit(code)


def fallback_count(summary: dict[str, Any]) -> int:
    """Segments whose material fell back in a run (0 for summaries without the count)."""
    return int((summary.get("fallbacks") or {}).get("segments", 0))


def print_generate_summary(summary: dict[str, Any]) -> None:
    """Human summary: counts, per-geometry table, seconds per stage, where things went."""
    from rich.markup import escape
    from rich.table import Table

    console = _console()
    c, fc = summary["counts"], summary["frame_counts"]
    console.print(
        f"[bold]{summary.get('unit', 'worlds')}: {c['ok']} computed, {c['skipped']} cached, "
        f"{c['failed']} failed; "
        f"frames: {fc['ok']} computed, {fc['skipped']} cached, {fc['failed']} failed[/bold] "
        f"— dataset {summary['dataset']!r}"
    )
    for w in summary["outcomes"]:
        if w["status"] != "failed":
            continue
        # errors carry "[stage]" prefixes: escaped, or rich would take them for markup
        console.print(f"  [red]✗ {w['id']}[/red]: {escape(w['error'])}")
        for f in w["parts"]:
            if f["status"] == "failed":
                console.print(f"      [red]{f['id']}[/red]: {escape(f['error'])}")
    table = Table(title="dataset summary (means per frame)")
    table.add_column("")
    geoms = list(summary["geometry"])
    for g in geoms:
        table.add_column(g, justify="right")
    rows = (("frames", "frames", "d"), ("radar points", "points_per_frame", ".1f"),
            ("door labels", "labels_per_frame", ".2f"),
            ("GT doors in radar view", "gt_doors_per_frame", ".2f"),
            ("frames with a label", "frac_frames_with_label", ".0%"),
            ("GT doors with radar points", "frac_gt_doors_with_points", ".0%"),
            ("label recall (3D IoU 0.3)", "label_recall", ".0%"),
            ("label precision (3D IoU 0.3)", "label_precision", ".0%"),
            ("matched label width error [m]", "label_width_error_m", ".2f"),
            ("points in a label box (median)", "points_per_label", ".1f"),
            ("label boxes without points", "labels_without_points", ".0%"),
            ("points > 1 m behind the true surface", "behind_surface_share", ".0%"),
            ("points beyond 0.85 R_max", "beyond_range_share", ".0%"))
    truth = ("GT", "label_recall", "label_precision", "label_width", "behind_surface")
    for name, key, fmt in rows:
        if not summary.get("ground_truth", True) and any(t in name or t in key for t in truth):
            continue  # a capture folder has no ground truth to compare with
        table.add_row(name, *(_fmt(summary["geometry"][g].get(key), fmt) for g in geoms))
    console.print(table)
    secs = summary.get("seconds_per_frame", {})
    if secs:
        console.print("seconds per frame: " + ", ".join(f"{k} {_fmt(v, '.2f')}"
                                                        for k, v in secs.items()))
    comp = summary.get("comparison")
    if comp:
        console.print(f"reconstructed vs ground truth: points ratio {_fmt(comp['points_ratio'], '.2f')}, "
                      f"radar Chamfer {_fmt(comp['chamfer_m'], '.3f')} m")
    fb = summary.get("fallbacks") or {}
    if fb.get("segments"):
        console.print(
            f"[yellow]fallbacks:[/yellow] {fb['segments']} segment material(s) fell back to "
            f"unknown (VLM failures) in {fb['scenes']} {summary.get('unit', 'worlds')}, "
            f"{fb['frames']} frame(s); stored as provisional: the next run asks again "
            "(--strict fails on them)")
    console.print(f"store:    {summary['store']}")
    console.print(f"manifest: {summary['manifest']}")
    for g, e in (summary.get("export") or {}).items():
        console.print(f"openpcdet \\[{g}]: {e['root']} ({e['frames']} frames, splits {e['splits']})")
        for w in e.get("warnings", []):
            console.print(f"  [yellow]warning:[/yellow] {escape(w)}")
    if summary.get("pngs"):
        console.print(f"pictures: {Path(summary['pngs'][0]).parent} ({len(summary['pngs'])} PNG)")
