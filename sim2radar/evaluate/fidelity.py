"""Where a radar frame's points are, measured against the true geometry: the fidelity figures
of simulated (and reference) radar frames of procedural worlds.

A radar point ``p`` (radar frame, range ``|p|``) lies on the ray from the radar through it; the
true scene's first surface along that ray is at ``d(p)`` [m] (``inf`` when the ray leaves the
scene). Its **surface offset** is ``|p| - d(p)``:

* ``~0`` — a return from the first surface (a wall, a door, the floor);
* ``> behind_m`` (1 m) — the point sits well behind the first surface: a multipath return
  (the radar places a path at its last interaction's direction and half its length) or a
  return through a slab (a door, plasterboard). The device shows some (multipath ghosts
  are physical); a haze of them is a defect of the model or its detector
  (docs/radar_model.md);
* ``< -behind_m`` — the point is in free space in front of the first surface.

**Beyond** ``far_fraction R_max`` (0.85: 8.25 m for the TI cascade): TI's detection chain tests
range bins only up to ``R_max`` minus its discarded and window cells (~0.87 ``R_max``) and the
anti-alias filter rolls off from 0.9 ``R_max``, so the device shows few points there.

Door figures: points inside each door label box (no margin), the share of label boxes with
none, and, for labels matched one-to-one to the ground-truth doors at 3D IoU >= 0.3
(:func:`sim2radar.evaluate.reconstruction.match_boxes`), the size error of the matched label.

Everything here is a pure function over arrays; the first-surface query is passed in
(:func:`sim2radar.factory.labels.scene_ray_caster` on the world's meshes).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from sim2radar.boxes import points_in_boxes

__all__ = [
    "BEHIND_SURFACE_M",
    "FAR_RANGE_FRACTION",
    "DomainFidelity",
    "FidelityCounts",
    "domain_fidelity",
    "fidelity_readings",
    "label_quality",
    "azimuth_coverage_deg",
    "heldout_world_seeds",
    "box_size_errors",
    "points_per_box",
    "surface_offsets",
]

#: A point more than this behind the first true surface along its ray counts as "behind" [m].
BEHIND_SURFACE_M = 1.0
#: A point beyond this fraction of the unambiguous range counts as "far" [-].
FAR_RANGE_FRACTION = 0.85


def surface_offsets(points: np.ndarray,
                    first_hit_distance: Callable[[np.ndarray, np.ndarray], np.ndarray]
                    ) -> np.ndarray:
    """(N,) float32 — each point's range minus the distance to the first true surface along
    its ray [m]: ``+inf`` where the ray meets no surface, NaN for a point at the origin.

    Parameters
    ----------
    points : (N, >=3) float — x, y, z [m], radar frame.
    first_hit_distance : callable ``(origins (N, 3), directions (N, 3)) -> (N,)`` [m] — the
        first surface along rays given in the radar frame (``inf`` on a miss).
    """
    p = np.asarray(points, dtype=np.float64)
    p = p.reshape(len(p), -1)[:, :3] if p.size else np.zeros((0, 3))
    r = np.linalg.norm(p, axis=1)
    out = np.full(len(p), np.nan, dtype=np.float64)
    ok = r > 1e-6
    if ok.any():
        d = p[ok] / r[ok, None]
        hit = np.asarray(first_hit_distance(np.zeros_like(d), d), dtype=np.float64)
        out[ok] = np.where(np.isfinite(hit), r[ok] - hit, np.inf)
    return out.astype(np.float32)


@dataclass(frozen=True)
class FidelityCounts:
    """Where the points of a set of frames are.

    Attributes
    ----------
    points : int — points with a surface offset (NaN offsets left out).
    behind : int — points more than ``behind_m`` behind the first surface (no surface
        counts as behind: nothing is there).
    beyond : int — points beyond ``far_m``.
    behind_m, far_m : float [m] — the thresholds used.
    """

    points: int
    behind: int
    beyond: int
    behind_m: float
    far_m: float

    @classmethod
    def of(cls, offsets_m: Sequence[np.ndarray], ranges_m: Sequence[np.ndarray],
           max_range_m: float, behind_m: float = BEHIND_SURFACE_M,
           far_fraction: float = FAR_RANGE_FRACTION) -> FidelityCounts:
        """Pool per-frame surface offsets and point ranges [m] (same order per frame)."""
        off = np.concatenate([np.asarray(o, np.float64).reshape(-1) for o in offsets_m]
                             or [np.zeros(0)])
        rng = np.concatenate([np.asarray(r, np.float64).reshape(-1) for r in ranges_m]
                             or [np.zeros(0)])
        if off.shape != rng.shape:
            raise ValueError(f"{off.size} surface offsets for {rng.size} point ranges")
        ok = ~np.isnan(off)
        far_m = far_fraction * float(max_range_m)
        return cls(points=int(ok.sum()), behind=int((off[ok] > behind_m).sum()),
                   beyond=int((rng[ok] > far_m).sum()), behind_m=float(behind_m),
                   far_m=float(far_m))

    @property
    def behind_share(self) -> float:
        """Share of points behind the first surface (NaN without points)."""
        return self.behind / self.points if self.points else float("nan")

    @property
    def beyond_share(self) -> float:
        """Share of points beyond ``far_m`` (NaN without points)."""
        return self.beyond / self.points if self.points else float("nan")

    def to_dict(self) -> dict[str, float | int]:
        return {"points": self.points, "behind": self.behind, "beyond": self.beyond,
                "behind_share": self.behind_share, "beyond_share": self.beyond_share,
                "behind_m": self.behind_m, "far_m": self.far_m}


def points_per_box(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """(M,) int32 — points inside each ``x y z dx dy dz heading`` box (no margin)."""
    return points_in_boxes(points, boxes).sum(axis=0).astype(np.int32)


def azimuth_coverage_deg(points: Sequence[np.ndarray],
                         percentiles: tuple[float, float] = (1.0, 99.0)) -> tuple[float, float]:
    """The (1 %, 99 %) azimuth percentiles [deg] of the points of all frames pooled
    (``atan2(y, x)``, + = left); NaN without points."""
    az = [np.degrees(np.arctan2(np.asarray(p)[:, 1], np.asarray(p)[:, 0]))
          for p in points if len(p)]
    if not az:
        return float("nan"), float("nan")
    lo, hi = np.percentile(np.concatenate(az), percentiles)
    return float(lo), float(hi)


def box_size_errors(pred: np.ndarray, gt: np.ndarray, pairs: Sequence[tuple[int, int]]
                    ) -> np.ndarray:
    """(K, 4) float64 — per matched (label, ground truth) pair: width (``dx``), depth
    (``dy``) and height (``dz``) error ``label - truth`` [m] and the centre distance [m]."""
    p = np.asarray(pred, np.float64).reshape(-1, 7)
    g = np.asarray(gt, np.float64).reshape(-1, 7)
    if not len(pairs):
        return np.zeros((0, 4))
    i, j = np.asarray(pairs, np.int64).T
    size = p[i, 3:6] - g[j, 3:6]
    centre = np.linalg.norm(p[i, :3] - g[j, :3], axis=1)
    return np.column_stack([size, centre])


def heldout_world_seeds(name: str = "heldout_worlds") -> list[int]:
    """The held-out validation world seeds (``configs/evaluation/<name>.yaml``, a bundled name
    or a path): fixed before the door and fidelity work of issue #29, never tuned on; every
    fidelity and door-label figure is reported on them (``python -m benchmarks fidelity``).

    Raises
    ------
    ValueError — the file has no list of integer ``seeds``.
    """
    from sim2radar.configio import config_path, read_yaml_mapping

    path = config_path(name, "evaluation", what="evaluation config")
    seeds = read_yaml_mapping(path, what="held-out worlds file").get("seeds")
    if not isinstance(seeds, list) or not seeds or not all(
            isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds):
        raise ValueError(f"{path}: 'seeds' must be a non-empty list of world seeds (integers "
                         f">= 0), got {seeds!r}")
    return list(seeds)


def label_quality(labels: Sequence[np.ndarray], truths: Sequence[np.ndarray],
                  iou_threshold: float = 0.3) -> dict[str, float | int]:
    """How a dataset's door labels compare with the true doors of the same frames (each
    label matched one-to-one by 3D IoU, :func:`sim2radar.evaluate.reconstruction.match_boxes`):
    ``labels``, ``true_doors``, ``recall``, ``precision`` (NaN without any) and the matched
    labels' mean absolute ``width_error_m``, ``depth_error_m``, ``height_error_m`` and mean
    ``centre_error_m`` [m] (:func:`box_size_errors`), at ``iou_threshold``.

    Parameters
    ----------
    labels, truths : per frame, (M, 7) and (G, 7) boxes ``x y z dx dy dz heading``.
    """
    from sim2radar.evaluate.reconstruction import match_boxes

    if len(labels) != len(truths):
        raise ValueError(f"{len(labels)} frames of labels for {len(truths)} of true doors")
    tp = n_pred = n_gt = 0
    errors = []
    for pred, gt in zip(labels, truths, strict=True):
        m = match_boxes(pred, gt, iou_threshold)
        tp, n_pred, n_gt = tp + m["tp"], n_pred + m["n_pred"], n_gt + m["n_gt"]
        errors.append(box_size_errors(pred, gt, m["pairs"]))
    err = np.abs(np.concatenate(errors)) if errors else np.zeros((0, 4))
    mean = err.mean(axis=0) if len(err) else np.full(4, np.nan)
    return {"iou_threshold": float(iou_threshold), "labels": int(n_pred), "true_doors": int(n_gt),
            "recall": tp / n_gt if n_gt else math.nan,
            "precision": tp / n_pred if n_pred else math.nan,
            "width_error_m": float(mean[0]), "depth_error_m": float(mean[1]),
            "height_error_m": float(mean[2]), "centre_error_m": float(mean[3])}


@dataclass(frozen=True)
class DomainFidelity:
    """The fidelity figures of one dataset of the gap report (NaN / None: not measurable).

    Attributes
    ----------
    behind_share, beyond_share : float or None — from its ``dataset.json["point_geometry"]``
        (written when the true geometry is known, i.e. procedural worlds; None otherwise).
    points_per_label : float — median points inside a door label box.
    labels_empty, labels_under_5 : float — share of label boxes with no / fewer than 5 points.
    azimuth_lo_deg, azimuth_hi_deg : float [deg] — 1 % and 99 % azimuth percentiles.
    label_recall, label_precision, label_width_error_m, label_depth_error_m : float or None —
        from its ``dataset.json["labels_vs_truth"]`` (:func:`label_quality`; None without).
    """

    behind_share: float | None
    beyond_share: float | None
    points_per_label: float
    labels_empty: float
    labels_under_5: float
    azimuth_lo_deg: float
    azimuth_hi_deg: float
    label_recall: float | None = None
    label_precision: float | None = None
    label_width_error_m: float | None = None
    label_depth_error_m: float | None = None

    def to_dict(self) -> dict:
        return asdict(self)


def domain_fidelity(points: Mapping[str, np.ndarray], labels: Mapping[str, np.ndarray],
                    point_geometry: Mapping | None = None,
                    labels_vs_truth: Mapping | None = None) -> DomainFidelity:
    """:class:`DomainFidelity` of a dataset: its frames' points and label boxes (by frame id;
    a frame without labels has none) and what its ``dataset.json`` measured against the true
    geometry (``point_geometry``, ``labels_vs_truth``; None when it does not know it)."""
    inside = np.concatenate([points_per_box(p, labels.get(fid, np.zeros((0, 7))))
                             for fid, p in points.items()] or [np.zeros(0, np.int32)])
    lo, hi = azimuth_coverage_deg(list(points.values()))
    geo = point_geometry or {}
    lab = labels_vs_truth or {}

    def opt(d: Mapping, key: str) -> float | None:
        v = d.get(key)
        return None if v is None else float(v)

    return DomainFidelity(
        behind_share=opt(geo, "behind_share"), beyond_share=opt(geo, "beyond_share"),
        points_per_label=float(np.median(inside)) if len(inside) else math.nan,
        labels_empty=float(np.mean(inside == 0)) if len(inside) else math.nan,
        labels_under_5=float(np.mean(inside < 5)) if len(inside) else math.nan,
        azimuth_lo_deg=lo, azimuth_hi_deg=hi,
        label_recall=opt(lab, "recall"), label_precision=opt(lab, "precision"),
        label_width_error_m=opt(lab, "width_error_m"),
        label_depth_error_m=opt(lab, "depth_error_m"))


def _ratio(a: float | None, b: float | None) -> str:
    if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)) or b <= 0:
        return ""
    return f" ({a / b:.1f}x)"


def fidelity_readings(sim: DomainFidelity, real: DomainFidelity) -> list[str]:
    """One plain sentence per figure of the gap report's fidelity section."""
    def pct(v: float | None) -> str:
        return "not measured (no true geometry)" if v is None or not math.isfinite(v) \
            else f"{100 * v:.0f} %"

    out = [
        f"Points more than {BEHIND_SURFACE_M:g} m behind the first true surface along their "
        f"ray (multipath, or seen through a slab): SIM {pct(sim.behind_share)}, REAL "
        f"{pct(real.behind_share)}{_ratio(sim.behind_share, real.behind_share)}.",
        f"Points beyond {FAR_RANGE_FRACTION:g} R_max (where the device's chain shows few): "
        f"SIM {pct(sim.beyond_share)}, REAL {pct(real.beyond_share)}"
        f"{_ratio(sim.beyond_share, real.beyond_share)}.",
        f"Points inside a door label box (median): SIM {sim.points_per_label:.0f}, REAL "
        f"{real.points_per_label:.0f}; boxes with none: SIM {pct(sim.labels_empty)}, REAL "
        f"{pct(real.labels_empty)}.",
        f"Azimuth covered by 98 % of the points: SIM {sim.azimuth_lo_deg:+.0f} to "
        f"{sim.azimuth_hi_deg:+.0f} deg, REAL {real.azimuth_lo_deg:+.0f} to "
        f"{real.azimuth_hi_deg:+.0f} deg.",
    ]
    if sim.label_recall is not None:
        out.append(f"SIM door labels against the true doors (3D IoU 0.3): recall "
                   f"{pct(sim.label_recall)}, precision {pct(sim.label_precision)}, matched "
                   f"width error {sim.label_width_error_m:.2f} m.")
    return out
