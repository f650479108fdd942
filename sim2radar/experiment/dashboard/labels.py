"""Names, colours and numbers as the dashboard shows them (shared by :mod:`.data` and
:mod:`.figures`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from sim2radar.experiment.profiles import CONDITIONS

__all__ = ["colour", "fmt", "metric_label", "num", "pct", "share", "signed"]

#: colours of conditions outside the registry (profiles.CONDITIONS holds the known ones')
MORE_COLOURS = ("#ff7f0e", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")


def num(v: Any) -> float | None:
    """``v`` as a finite float; None for None, a bool, a non-number, NaN or ±inf."""
    if v is None or isinstance(v, bool):
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def pct(fraction: float) -> str:
    """``0.25`` -> ``25 %``."""
    return f"{100 * fraction:g} %"


def fmt(v: Any, spec: str = ",.1f") -> str:
    """A number for a fact table: integers with thousands separators, floats with ``spec``;
    ``—`` for None, a non-number as its text."""
    if isinstance(v, int) and not isinstance(v, bool):
        return f"{v:,}"
    f = num(v)
    if f is None:
        return "—" if v is None else str(v)
    return format(f, spec)


def share(v: Any) -> str:
    """A share in [0, 1] as a percentage: ``0.25`` -> ``25.0 %``; ``—`` for none."""
    f = num(v)
    return "—" if f is None else f"{100 * f:.1f} %"


def signed(v: Any, digits: int = 1) -> str:
    """A signed number with a typographic minus (``+1.2``, ``−0.8``); ``—`` for none."""
    f = num(v)
    return "—" if f is None else format(f, f"+.{digits}f").replace("-", "\u2212")


def metric_label(metric: str) -> str:
    """``ap_3d_r40_iou03`` -> ``3D AP R40 @ IoU 0.3``."""
    try:
        _, kind, rp, iou = metric.split("_")
        return f"{kind.upper()} AP {rp.upper()} @ IoU {iou[3]}.{iou[4:]}"
    except ValueError:
        return metric


def colour(condition: str, conditions: Sequence[str]) -> str:
    """The condition's registered colour (:data:`~sim2radar.experiment.profiles.CONDITIONS`);
    a condition outside the registry takes the next of :data:`MORE_COLOURS` in the order of
    ``conditions``."""
    if condition in CONDITIONS:
        return CONDITIONS[condition].colour
    others = [c for c in conditions if c not in CONDITIONS]
    return MORE_COLOURS[others.index(condition) % len(MORE_COLOURS)]
