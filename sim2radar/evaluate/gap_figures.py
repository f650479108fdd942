"""The figures of the sim–real gap report: matplotlib PNGs of a ``GapReport``.

:func:`overlay_png` draws one frame's sim and real points on top of each other (the paper's
Figure 3: sim in red, real in blue); :func:`gap_figures` draws the azimuth, range, intensity,
points-per-frame and artefact figures of a
:class:`~sim2radar.evaluate.gap_metrics.GapReport`. :data:`FIGURES` names the file each is
written to in the report folder (:func:`sim2radar.evaluate.gap.write_gap_report`).
matplotlib is imported inside the functions that draw, so importing this module stays cheap.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

from sim2radar.evaluate.fidelity import BEHIND_SURFACE_M, FAR_RANGE_FRACTION, DomainFidelity
from sim2radar.evaluate.gap_metrics import GapReport
from sim2radar.fileio import atomic_write

__all__ = ["FIGURES", "fidelity_png", "gap_figures", "overlay_png"]

#: Figure names in ``gap.json`` -> file names in the report folder.
FIGURES = {"overlay": "overlay.png", "azimuth": "azimuth.png", "range": "range.png",
           "intensity": "intensity.png", "points": "points.png", "artefacts": "artefacts.png",
           "fidelity": "fidelity.png"}

_SIM_COLOR = "tab:red"  # the paper's Figure 3: simulated radar in red
_REAL_COLOR = "tab:blue"  # ... and real radar in blue


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def _new_figure(width_in: float, height_in: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def overlay_png(
    sim_points: np.ndarray,
    real_points: np.ndarray,
    *,
    title: str,
    boxes: np.ndarray | None = None,
    side_view: bool = True,
    path: str | Path | None = None,
    size_px: int = 800,
) -> bytes:
    """Sim (red) and real (blue) points of one frame on top of each other (paper Figure 3).

    Left: bird's-eye view, x forward up the page, y left to the left (as
    :func:`sim2radar.visualize.bev_png`), the radar as a black triangle at the origin. Right
    (``side_view``): the same x axis up the page against height z [m], so a point sits at the
    same height on the page in both panels.

    Parameters
    ----------
    sim_points, real_points : (N, ≥3), (M, ≥3) float — x, y, z [m] in the radar frame.
    title : str — figure title (e.g. both point counts and their ratio).
    boxes : (K, 7), optional — ``x y z dx dy dz heading`` labels drawn as black outlines.
    side_view : bool — add the x–z panel.
    path : optional — also write the PNG there (parent folders created).
    size_px : int — image height [px].

    Returns
    -------
    bytes — the PNG.
    """
    from matplotlib.patches import Polygon

    from sim2radar.visualize import box_corners_xy

    sp = np.asarray(sim_points, dtype=np.float64).reshape(-1, np.shape(sim_points)[-1])[:, :3]
    rp = np.asarray(real_points, dtype=np.float64).reshape(-1, np.shape(real_points)[-1])[:, :3]
    bxs = np.zeros((0, 7)) if boxes is None else np.asarray(boxes, np.float64).reshape(-1, 7)
    corners = box_corners_xy(bxs)
    allp = np.concatenate([np.zeros((1, 3)), sp, rp])
    pad = 0.5
    x0, x1 = allp[:, 0].min() - pad, allp[:, 0].max() + pad
    y0, y1 = allp[:, 1].min() - pad, allp[:, 1].max() + pad
    if len(corners):
        x0, x1 = min(x0, corners[..., 0].min() - pad), max(x1, corners[..., 0].max() + pad)
        y0, y1 = min(y0, corners[..., 1].min() - pad), max(y1, corners[..., 1].max() + pad)
    z0, z1 = allp[:, 2].min() - pad, allp[:, 2].max() + pad
    if len(bxs):
        z0 = min(z0, float((bxs[:, 2] - bxs[:, 5] / 2).min()) - pad)
        z1 = max(z1, float((bxs[:, 2] + bxs[:, 5] / 2).max()) + pad)
    bev_w = float(np.clip((y1 - y0) / max(x1 - x0, 1e-6), 0.4, 2.5))
    side_w = float(np.clip((z1 - z0) / max(x1 - x0, 1e-6), 0.15, 1.0)) if side_view else 0.0
    h_in = size_px / 100
    fig = _new_figure(h_in * (bev_w + side_w) + 1.0, h_in)
    axes = fig.subplots(1, 2 if side_view else 1, sharey=True, squeeze=False,
                        width_ratios=[bev_w, side_w] if side_view else None)[0]
    ax = axes[0]
    for corner in corners:
        ax.add_patch(Polygon(corner[:, ::-1], closed=True, fill=False, edgecolor="k", lw=1.0,
                             ls="--", zorder=3))
    ax.scatter(rp[:, 1], rp[:, 0], s=3, color=_REAL_COLOR, linewidths=0, alpha=0.6,
               label=f"real ({len(rp):,})", zorder=1)
    ax.scatter(sp[:, 1], sp[:, 0], s=7, color=_SIM_COLOR, linewidths=0, alpha=0.9,
               label=f"sim ({len(sp):,})", zorder=2)
    ax.plot([0], [0], marker="^", color="k", ms=8, ls="none", zorder=4)
    ax.set_xlim(y1, y0)  # +y to the left
    ax.set_ylim(x0, x1)
    ax.set_aspect("equal")
    ax.set_xlabel("y (left) [m]")
    ax.set_ylabel("x (forward) [m]")
    ax.set_title("bird's-eye view", fontsize=9)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(loc="lower right", fontsize=8, markerscale=2)
    if side_view:
        sx = axes[1]
        sx.scatter(rp[:, 2], rp[:, 0], s=3, color=_REAL_COLOR, linewidths=0, alpha=0.6)
        sx.scatter(sp[:, 2], sp[:, 0], s=7, color=_SIM_COLOR, linewidths=0, alpha=0.9)
        sx.plot([0], [0], marker="^", color="k", ms=8, ls="none")
        sx.set_xlim(z0, z1)
        sx.set_aspect("equal")
        sx.set_xlabel("z (up) [m]")
        sx.set_title("side view", fontsize=9)
        sx.grid(True, lw=0.3, alpha=0.5)
    fig.suptitle(title, fontsize=10)
    data = _png(fig)
    _maybe_write(path, data)
    return data


def _maybe_write(path: str | Path | None, data: bytes) -> None:
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, data)


def _steps(ax, edges, frac, **kw) -> None:
    ax.stairs(100 * np.asarray(frac), np.asarray(edges), **kw)


def _azimuth_png(rep: GapReport) -> bytes:
    fig = _new_figure(8, 4.5)
    ax = fig.subplots()
    e = rep.azimuth_edges_deg
    for frac, fov, color, name in ((rep.azimuth_real, rep.fov_real, _REAL_COLOR, "real"),
                                   (rep.azimuth_sim, rep.fov_sim, _SIM_COLOR, "sim")):
        _steps(ax, e, frac, color=color,
               label=f"{name}: effective FOV {_fmt(fov.width_deg, '.1f')}°")
        if math.isfinite(fov.width_deg):
            for lo, hi in _unwrap(fov.lo_deg, fov.hi_deg):
                ax.axvspan(lo, hi, color=color, alpha=0.08, lw=0)
    used = np.flatnonzero((rep.azimuth_sim > 0) | (rep.azimuth_real > 0))
    lim = 75.0
    if used.size:
        lim = max(lim, float(np.abs(e[[used[0], used[-1] + 1]]).max()) + 5.0)
    ax.set_xlim(min(lim, 180.0), -min(lim, 180.0))  # +azimuth (left) to the left, as in the BEV
    ax.set_xlabel("azimuth atan2(y, x) [deg] (positive = left)")
    ax.set_ylabel(f"points per {rep.settings.azimuth_bin_deg:g}° bin [%]")
    ax.set_title(f"azimuth coverage (shaded: smallest interval holding "
                 f"{100 * rep.settings.fov_coverage:g} % of points)", fontsize=10)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize=8)
    return _png(fig)


def _unwrap(lo: float, hi: float) -> list[tuple[float, float]]:
    """An interval that may run past 180° as one or two pieces inside [-180, 180]."""
    if hi <= 180.0:
        return [(lo, hi)]
    return [(lo, 180.0), (-180.0, hi - 360.0)]


def _range_png(rep: GapReport) -> bytes:
    fig = _new_figure(8, 4.5)
    ax = fig.subplots()
    e = rep.range_edges_m
    _steps(ax, e, rep.range_real, color=_REAL_COLOR, label="real")
    _steps(ax, e, rep.range_sim, color=_SIM_COLOR, label="sim")
    ax.set_xlabel("range |(x, y, z)| [m]")
    ax.set_ylabel(f"points per {e[1] - e[0]:g} m bin [%]")
    ax.set_title("range coverage", fontsize=10)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize=8)
    return _png(fig)


def _intensity_png(rep: GapReport) -> bytes:
    fig = _new_figure(8, 4.5)
    ax = fig.subplots()
    e = rep.intensity_edges_db
    _steps(ax, e, rep.intensity_real, color=_REAL_COLOR, fill=True, alpha=0.35, label="real")
    _steps(ax, e, rep.intensity_sim_before, color=_SIM_COLOR, ls="--", alpha=0.7,
           label="sim (as simulated)")
    _steps(ax, e, rep.intensity_sim_after, color=_SIM_COLOR, label="sim (histogram-matched)")
    ax.set_xlabel("intensity [dB]")
    ax.set_ylabel(f"points per {e[1] - e[0]:.3g} dB bin [%]")
    ax.set_title("intensity distributions (log-space histogram matching)", fontsize=10)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize=8)
    return _png(fig)


def _points_png(rep: GapReport) -> bytes:
    fig = _new_figure(8, 4.5)
    ax = fig.subplots()
    top = max(int(rep.sim.counts.max(initial=0)), int(rep.real.counts.max(initial=0)), 1)
    edges = np.linspace(0, top * 1.02 + 1, 41)
    for st, color, name in ((rep.real, _REAL_COLOR, "real"), (rep.sim, _SIM_COLOR, "sim")):
        if st.frames:
            ax.hist(st.counts, bins=edges, color=color, alpha=0.5,
                    label=f"{name}: mean {st.mean:,.0f}, median {st.median:,.0f} "
                          f"({st.frames} frames)")
            ax.axvline(st.mean, color=color, ls="--", lw=1)
    ax.set_xlabel("points per frame")
    ax.set_ylabel("frames")
    ax.set_title(f"points per frame — sim/real density {_pct(rep.points_ratio)}", fontsize=10)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize=8)
    return _png(fig)


def _artefacts_png(rep: GapReport) -> bytes:
    """Three panels: sidelobe share vs its control, Doppler histograms, range > far_range_m
    and below-floor shares; a figure a dataset lacks is written on its panel, not drawn as 0."""
    s = rep.settings.artefacts
    fig = _new_figure(15, 4.8)
    ax_side, ax_dop, ax_share = fig.subplots(1, 3, width_ratios=[1.0, 1.6, 1.1])
    roles = (("sim", rep.artefacts_sim, rep.info_sim, _SIM_COLOR),
             ("real", rep.artefacts_real, rep.info_real, _REAL_COLOR))
    names = [f"{role}\n({_short(info.domain)})" for role, _, info, _ in roles]
    x = np.arange(len(roles))
    w = 0.38
    for k, (_, a, _, color) in enumerate(roles):
        for dx, value, kw, lab in ((-w / 2, a.sidelobe.share, {}, "sidelobe bins"),
                                   (w / 2, a.sidelobe.control_share,
                                    {"hatch": "//", "fill": False}, "control bins")):
            v = 100 * value if math.isfinite(value) else 0.0
            ax_side.bar(x[k] + dx, v, w, color=color, edgecolor=color,
                        label=lab if k == 0 else None, **kw)
            ax_side.annotate(_fmt(100 * value, ".1f"), (x[k] + dx, v), ha="center",
                             va="bottom", fontsize=8)
    tallest = max((100 * v for _, a, _, _ in roles
                   for v in (a.sidelobe.share, a.sidelobe.control_share) if math.isfinite(v)),
                  default=0.0)
    ax_side.set_ylim(0.0, max(tallest, 1.0) * 1.3)  # headroom for the legend
    ax_side.set_xticks(x, names, fontsize=8)
    ax_side.set_ylabel("points [%]")
    ax_side.set_title(f"on a ≥{s.sidelobe_min_drop_db:g} dB stronger return's range bin "
                      f"±{s.sidelobe_range_tolerance_bins}\n(>{s.sidelobe_min_separation_deg:g}° "
                      f"away; control: ±{s.sidelobe_control_offset_bins} bins)", fontsize=9)
    ax_side.legend(fontsize=8, loc="upper right")
    ax_side.grid(True, axis="y", lw=0.3, alpha=0.5)

    missing, top = [], 0.0
    for role, a, _, color in roles:
        if a.doppler is None or rep.doppler_edges_mps is None:
            missing.append(role)
            continue
        _steps(ax_dop, rep.doppler_edges_mps, a.doppler.fraction, color=color,
               label=f"{role}: moving {_fmt(100 * a.doppler.moving_share, '.1f')} %, "
                     f"median |v| {_fmt(a.doppler.abs_median_mps, '.2f')} m/s")
        top = max(top, 100 * float(np.max(a.doppler.fraction, initial=0.0)))
    if rep.doppler_edges_mps is not None:
        ax_dop.legend(fontsize=8, loc="upper left")
        ax_dop.set_yscale("symlog", linthresh=0.1)
        ax_dop.set_ylim(0.0, max(top, 1.0) * 30)  # headroom for the legend (log axis)
    else:
        ax_dop.text(0.5, 0.5, "no Doppler column in either dataset", ha="center",
                    transform=ax_dop.transAxes, fontsize=9)
        ax_dop.set_xticks([])
        ax_dop.set_yticks([])
    ax_dop.set_xlabel("Doppler [m/s]")
    ax_dop.set_ylabel(f"points per {s.doppler_bin_mps:g} m/s bin [%]")
    ax_dop.set_title(f"Doppler (moving: |v| > {s.doppler_bin_mps / 2:g} m/s)"
                     + "".join(f"\n{role}: no Doppler column (not drawn)" for role in missing),
                     fontsize=9)
    ax_dop.grid(True, lw=0.3, alpha=0.5)

    groups = [f"range > {s.far_range_m:g} m", f"> {s.below_floor_margin_m:g} m below floor"]
    gx = np.arange(len(groups))
    for k, (role, a, _, color) in enumerate(roles):
        dx = (k - 0.5) * w
        for g, value in enumerate((a.beyond_range_share, a.below_floor_share)):
            known = value is not None and math.isfinite(value)
            v = 100 * value if known else 0.0
            ax_share.bar(gx[g] + dx, v, w, color=color, label=role if g == 0 else None)
            ax_share.annotate(_fmt(v, ".1f") if known else "unknown", (gx[g] + dx, v),
                              ha="center", va="bottom", fontsize=8,
                              rotation=0 if known else 90)
    ax_share.set_xticks(gx, groups, fontsize=8)
    ax_share.set_ylabel("points [%]")
    ax_share.set_title("range coverage and points below the floor", fontsize=9)
    ax_share.legend(fontsize=8)
    ax_share.grid(True, axis="y", lw=0.3, alpha=0.5)
    return _png(fig)


def fidelity_png(sim: DomainFidelity, real: DomainFidelity, sim_domain: str = "sim",
                 real_domain: str = "real") -> bytes:
    """Two panels: where the points are and what the door labels hold, per dataset (shares
    [%]: behind the first true surface, beyond 0.85 R_max, door label boxes without points
    and with fewer than 5), and the median points inside a door label box. A figure a dataset
    cannot measure (no true geometry) is written as "unknown", not drawn as 0."""
    fig = _new_figure(12, 4.4)
    ax_share, ax_door = fig.subplots(1, 2, width_ratios=[2.2, 1.0])
    groups = [f"> {BEHIND_SURFACE_M:g} m behind\nthe first surface",
              f"beyond {FAR_RANGE_FRACTION:g} R_max", "door boxes\nwithout points",
              "door boxes\n< 5 points"]
    gx = np.arange(len(groups))
    w = 0.38
    sides = (("sim", sim, sim_domain, _SIM_COLOR), ("real", real, real_domain, _REAL_COLOR))
    for k, (role, f, domain, color) in enumerate(sides):
        dx = (k - 0.5) * w
        values = (f.behind_share, f.beyond_share, f.labels_empty, f.labels_under_5)
        for g, value in enumerate(values):
            known = value is not None and math.isfinite(value)
            v = 100 * value if known else 0.0
            ax_share.bar(gx[g] + dx, v, w, color=color,
                         label=f"{role} ({_short(domain)})" if g == 0 else None)
            ax_share.annotate(_fmt(v, ".1f") if known else "unknown", (gx[g] + dx, v),
                              ha="center", va="bottom", fontsize=8, rotation=0 if known else 90)
    ax_share.set_xticks(gx, groups, fontsize=8)
    ax_share.set_ylabel("points or boxes [%]")
    ax_share.set_ylim(0, 110)
    ax_share.set_title("where the points are (against the true geometry) and door label boxes",
                       fontsize=9)
    ax_share.legend(fontsize=8, loc="upper right")
    ax_share.grid(True, axis="y", lw=0.3, alpha=0.5)
    for k, (_, f, _, color) in enumerate(sides):
        v = f.points_per_label if math.isfinite(f.points_per_label) else 0.0
        ax_door.bar(k, v, 0.6, color=color)
        ax_door.annotate(_fmt(f.points_per_label, ".0f"), (k, v), ha="center", va="bottom",
                         fontsize=8)
    ax_door.set_xticks([0, 1], ["sim", "real"], fontsize=8)
    ax_door.set_ylabel("points in a door label box (median)")
    ax_door.set_title("the door signal", fontsize=9)
    ax_door.grid(True, axis="y", lw=0.3, alpha=0.5)
    return _png(fig)


def _short(text: str, n: int = 28) -> str:
    return text if len(text) <= n else text[:n - 1] + "…"


def gap_figures(rep: GapReport) -> dict[str, bytes]:
    """PNG bytes of the azimuth, range, intensity, points and artefacts figures (keys of
    :data:`FIGURES` less ``overlay``, which needs one frame's points: :func:`overlay_png`)."""
    return {"azimuth": _azimuth_png(rep), "range": _range_png(rep),
            "intensity": _intensity_png(rep), "points": _points_png(rep),
            "artefacts": _artefacts_png(rep)}


def _fmt(v: float, spec: str) -> str:
    return format(v, spec) if v is not None and math.isfinite(v) else "n/a"


def _pct(ratio: float) -> str:
    return f"{100 * ratio:.0f} %" if math.isfinite(ratio) else "n/a"

