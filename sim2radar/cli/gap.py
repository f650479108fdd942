"""``sim2radar gap``: the sim–real gap report of two radar datasets (paper §4.3, Figure 3).

    sim2radar gap out/openpcdet/reconstructed out/openpcdet/proxy_real_paired --out out/gap
    sim2radar gap data/sim data/ifr --out gap --max-frames 200 --frame world_000003_f001

Writes ``gap.json`` (points per frame and their ratio, azimuth/range coverage, effective
azimuth FOV, intensity histograms before/after log-space matching, Chamfer distance of frames
with a shared id, and per dataset its domain and artefact figures: sidelobe share vs control,
Doppler, range beyond 8 m, points below the floor) and ``overlay.png``, ``azimuth.png``,
``range.png``, ``intensity.png``, ``points.png``, ``artefacts.png`` (see
:func:`sim2radar.evaluate.gap.write_gap_report`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import typer

from sim2radar.cli._app import app

__all__ = ["artefact_lines", "gap", "print_gap_summary"]


def _num(v: Any, spec: str) -> str:
    return format(v, spec) if isinstance(v, int | float) and math.isfinite(v) else "n/a"


def _share(v: Any) -> str:
    return f"{_num(100 * v, '.1f')} %" if isinstance(v, int | float) else "n/a"


def artefact_lines(doc: dict[str, Any]) -> list[str]:
    """One line per domain (sim, real) with its artefact figures from ``gap.json``
    (:func:`sim2radar.evaluate.gap.artefacts_dict`); none for a report without them."""
    art = doc.get("artefacts")
    if not isinstance(art, dict):
        return []
    st = art.get("settings") or {}
    far, margin = st.get("far_range_m"), st.get("below_floor_margin_m")
    lines = []
    for role in ("sim", "real"):
        a = art.get(role) or {}
        diff = a.get("sidelobe_difference")
        dop = a.get("doppler")
        if isinstance(dop, dict):
            doppler = (f"Doppler moving {_share(dop.get('moving_share'))} "
                       f"(median |v| {_num(dop.get('abs_median_mps'), '.2f')} m/s)")
        else:
            doppler = a.get("doppler_note") or "no Doppler"
        below = a.get("below_floor_share")
        floor = (f"{_share(below)} > {_num(margin, 'g')} m below the floor "
                 f"(radar {_num(a.get('radar_height_m'), '.2f')} m up)" if below is not None
                 else "below floor: unknown (no radar_height_m in dataset.json)")
        lines.append(
            f"{role:4s} artefacts [domain: {doc.get(role, {}).get('domain', 'undeclared')}]: "
            f"sidelobe bins {_share(a.get('sidelobe_share'))} vs control "
            f"{_share(a.get('sidelobe_control_share'))} "
            f"({'+' if isinstance(diff, int | float) and diff >= 0 else ''}"
            f"{_num(100 * diff if isinstance(diff, int | float) else None, '.1f')} points); "
            f"{doppler}; range > {_num(far, 'g')} m {_share(a.get('beyond_range_share'))}; "
            f"{floor}")
    return lines


def print_gap_summary(doc: dict[str, Any], out: Path, fov_coverage: float = 0.95) -> None:
    """Print the short summary of a ``gap.json`` document written into ``out`` (its effective
    FOV measured with ``fov_coverage``)."""
    for role in ("sim", "real"):
        d = doc[role]
        typer.echo(f"{role:4s} {d['root']}: {d['frames']} frames, "
                   f"{_num(d['points_per_frame_mean'], ',.1f')} points/frame "
                   f"(median {_num(d['points_per_frame_median'], ',.0f')})")
    ratio = doc["points_ratio"]
    typer.echo(f"points ratio sim/real: {_num(100 * ratio if ratio is not None else None, '.1f')} %")
    fov = doc["azimuth"]["effective_fov_deg"]
    typer.echo(f"effective azimuth FOV: sim {_num(fov['sim'], '.1f')}°, "
               f"real {_num(fov['real'], '.1f')}° (smallest azimuth interval holding "
               f"{100 * fov_coverage:g} % of the points)")
    ch = doc["chamfer"]
    if ch is None:
        typer.echo("Chamfer: no frame id in both datasets (different scenes)")
    else:
        typer.echo(f"Chamfer ({ch['pairs']} shared frames): mean {_num(ch['mean_m'], '.3f')} m")
    typer.echo(f"intensity match fitted on {doc['intensity']['fitted_on']}")
    for line in artefact_lines(doc):
        typer.echo(line)
    files = ", ".join(["gap.json", *doc["figures"].values()])
    typer.echo(f"wrote {out}/: {files}")


@app.command()
def gap(
    sim: Annotated[Path, typer.Argument(help="Simulated dataset (OpenPCDet custom layout).")],
    real: Annotated[Path, typer.Argument(
        help="Reference dataset: measured radar or the proxy-real reference radar.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Report folder (created).")],
    max_frames: Annotated[int | None, typer.Option(
        "--max-frames", min=1, help="Analyse at most the first N frame ids of each dataset.")
    ] = None,
    frame: Annotated[str | None, typer.Option(
        "--frame",
        help="Frame id to overlay (default: the shared frame with the median Chamfer distance).")
    ] = None,
) -> None:
    """Sim–real gap report: density, coverage, FOV, intensities, Chamfer, artefacts, overlay."""
    from sim2radar.evaluate.gap import GapSettings, write_gap_report

    settings = GapSettings()
    try:
        doc = write_gap_report(sim, real, out, max_frames=max_frames, overlay_frame=frame,
                               settings=settings)
    except (ValueError, FileNotFoundError) as exc:  # DatasetError is a ValueError
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None
    print_gap_summary(doc, out, settings.fov_coverage)
