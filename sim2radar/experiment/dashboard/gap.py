"""The dashboard's sim–real gap section: the tables of ``gap/gap.json`` (written by
:func:`sim2radar.evaluate.gap.write_gap_report`) and its figures, drawn with Plotly from the
report's numbers (:mod:`.gap_plots`). Pure functions of the ``gap.json`` document.

    gap_section(gap, images) -> dict | None  the page's section
    png_fallbacks(gap) -> list[str]          the figures to show as the report's PNG

A report holds the numbers of every figure but the overlay and the points-per-frame histogram
when it was written before those were added to ``gap.json``; those two (and a figure this
page does not know) are then shown as the report's PNG, and the page says why.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from sim2radar.experiment.dashboard.gap_plots import GAP_PLOTS
from sim2radar.experiment.dashboard.labels import fmt, num, share
from sim2radar.fileio import jsonable

__all__ = ["gap_section", "png_fallbacks"]


def png_fallbacks(gap: Mapping[str, Any]) -> list[str]:
    """The figures of ``gap["figures"]`` (name -> PNG file) the page shows as their PNG: those
    whose numbers the report lacks (:attr:`~.gap_plots.GapPlot.has_numbers`) and those the
    page has no figure for."""
    figures = gap.get("figures")
    if not isinstance(figures, Mapping):
        return []
    return [str(name) for name in figures
            if name not in GAP_PLOTS or not GAP_PLOTS[name].has_numbers(gap)]


def _figures(gap: Mapping[str, Any], images: Mapping[str, str]) -> dict[str, Any]:
    """``figures`` (Plotly, from the numbers), ``images`` (PNG fallbacks) and
    ``image_note``."""
    figures = [{"name": name, "title": plot.title, "figure": plot.figure(gap)}
               for name, plot in GAP_PLOTS.items() if plot.has_numbers(gap)]
    shown = [{"name": name, "title": GAP_PLOTS[name].title if name in GAP_PLOTS else name,
              "uri": uri} for name, uri in images.items()]
    note = None
    if shown:
        names = ", ".join(i["name"] for i in shown)
        note = (f"Shown as the report's PNG ({names}): this gap.json holds no numbers for "
                "them (a report written before they were added to gap.json). Rerun `sim2radar "
                "gap SIM REAL --out <sweep>/gap` to draw them here with hover and zoom.")
    return {"figures": figures, "images": shown, "image_note": note}


def _gap_artefact_rows(art: Any) -> list[list[str]]:
    """Rows [label, sim, real] of ``gap.json["artefacts"]`` (sim2radar.evaluate.gap
    .artefacts_dict); "—" cells for a report without them (written before they existed)."""
    art = art if isinstance(art, Mapping) else {}
    st = art.get("settings") if isinstance(art.get("settings"), Mapping) else {}
    sides = [a if isinstance(a, Mapping) else {} for a in (art.get("sim"), art.get("real"))]
    far, margin = num(st.get("far_range_m")), num(st.get("below_floor_margin_m"))

    def sidelobe(a: Mapping) -> str:
        on, ctl = num(a.get("sidelobe_share")), num(a.get("sidelobe_control_share"))
        if on is None and ctl is None:
            return "—"
        return f"{share(on)} / {share(ctl)}"

    def doppler(a: Mapping) -> str:
        d = a.get("doppler")
        if isinstance(d, Mapping):
            med = num(d.get("abs_median_mps"))
            return (f"{share(d.get('moving_share'))} (median |v| "
                    f"{'—' if med is None else f'{med:.2f}'} m/s)")
        return str(a.get("doppler_note") or "—")

    def below(a: Mapping) -> str:
        if a.get("below_floor_share") is None:
            return str(a.get("below_floor_note") or "—")
        return share(a.get("below_floor_share"))

    return [
        ["sidelobe-bin share / control", *(sidelobe(a) for a in sides)],
        ["Doppler: moving share", *(doppler(a) for a in sides)],
        [f"range > {'8' if far is None else f'{far:g}'} m",
         *(share(a.get("beyond_range_share")) for a in sides)],
        [f"> {'0.1' if margin is None else f'{margin:g}'} m below the floor",
         *(below(a) for a in sides)],
    ]


def _gap_fidelity_rows(fid: Any) -> list[list[str]]:
    """Rows [label, sim, real] of ``gap.json["fidelity"]`` (sim2radar.evaluate.gap: where the
    points are against the true geometry, the door label boxes); none for a report written
    before it existed."""
    if not isinstance(fid, Mapping):
        return []
    sides = [f if isinstance(f, Mapping) else {} for f in (fid.get("sim"), fid.get("real"))]

    def known(v: Any, text: str) -> str:
        return "not measured (no true geometry)" if v is None else text

    def azimuth(f: Mapping) -> str:
        lo, hi = num(f.get("azimuth_lo_deg")), num(f.get("azimuth_hi_deg"))
        return "—" if lo is None or hi is None else f"{lo:+.0f}° to {hi:+.0f}°"

    def labels(f: Mapping) -> str:
        if f.get("label_recall") is None:
            return "—"
        return (f"{share(f.get('label_recall'))} / {share(f.get('label_precision'))}"
                f" (width error {fmt(f.get('label_width_error_m'), '.2f')} m)")

    return [
        ["points > 1 m behind the first true surface",
         *(known(f.get("behind_share"), share(f.get("behind_share"))) for f in sides)],
        ["points beyond 0.85 R_max",
         *(known(f.get("beyond_share"), share(f.get("beyond_share"))) for f in sides)],
        ["points in a door label box (median)",
         *(fmt(f.get("points_per_label"), ".0f") for f in sides)],
        ["door label boxes without points", *(share(f.get("labels_empty")) for f in sides)],
        ["azimuth covered (1–99 %)", *(azimuth(f) for f in sides)],
        ["door labels vs true doors: recall / precision", *(labels(f) for f in sides)],
    ]


def gap_section(gap: Mapping[str, Any] | None, images: Mapping[str, str] | None = None,
                ) -> dict[str, Any] | None:
    """The page's sim–real gap section, from ``gap.json`` and the PNGs read for the figures it
    holds no numbers for.

    Parameters
    ----------
    gap : ``gap/gap.json`` (None: the sweep has no gap report).
    images : figure name -> ``data:`` URI of its PNG (:attr:`~.reading.SweepData.gap_images`:
        only those :func:`png_fallbacks` names).

    Returns
    -------
    None without a report; else ``rows`` ([label, sim, real] strings), ``facts`` ([label,
    text]), ``figures`` (``[{"name", "title", "figure"}]``: the Plotly figures drawn from the
    numbers, :data:`~.gap_plots.GAP_PLOTS` order), ``images`` (``[{"name", "title", "uri"}]``:
    the PNGs shown in their place) and ``image_note`` (why those are PNGs; None without one).
    """
    if gap is None:
        return None
    sim, real = gap.get("sim") or {}, gap.get("real") or {}
    fov = (gap.get("azimuth") or {}).get("effective_fov_deg") or {}
    rows = [["frames analysed", fmt(sim.get("frames")), fmt(real.get("frames"))],
            ["points per frame (mean)", fmt(sim.get("points_per_frame_mean")),
             fmt(real.get("points_per_frame_mean"))],
            ["points per frame (median)", fmt(sim.get("points_per_frame_median")),
             fmt(real.get("points_per_frame_median"))],
            ["effective azimuth FOV [°]", fmt(fov.get("sim")), fmt(fov.get("real"))],
            ["domain (dataset.json)", str(sim.get("domain") or "—"),
             str(real.get("domain") or "—")],
            *_gap_artefact_rows(gap.get("artefacts")),
            *_gap_fidelity_rows(gap.get("fidelity")),
            ["dataset folder", str(sim.get("root", "—")), str(real.get("root", "—"))]]
    ratio = num(gap.get("points_ratio"))
    ch = gap.get("chamfer")
    facts = [["points ratio sim / real", "—" if ratio is None else f"{100 * ratio:.1f} %"],
             ["Chamfer distance (shared frames)",
              "no frame id in both datasets" if not isinstance(ch, Mapping) else
              f"{fmt(ch.get('mean_m'), '.3f')} m over {ch.get('pairs')} frame(s)"],
             ["intensity matching fitted on",
              str((gap.get("intensity") or {}).get("fitted_on", "—"))],
             ["overlay frame", str(gap.get("overlay_frame") or "—")]]
    definition = (gap.get("azimuth") or {}).get("definition")
    if definition:
        facts.append(["effective FOV", str(definition)])
    art = gap.get("artefacts")
    defs = (art.get("definitions") if isinstance(art, Mapping) else None) or {}
    if isinstance(defs, Mapping):
        for key, label in (("sidelobe", "sidelobe share"), ("doppler", "Doppler"),
                           ("beyond_range", "range coverage"), ("below_floor", "below floor")):
            if defs.get(key):
                facts.append([label, str(defs[key])])
    fid = gap.get("fidelity")
    readings = fid.get("readings") if isinstance(fid, Mapping) else None
    if isinstance(readings, list):
        facts += [["reading", str(r)] for r in readings]
    return jsonable({"rows": rows, "facts": facts, **_figures(gap, images or {})})
