"""Log-space histogram matching of radar intensities (paper §6.1).

Simulated and measured radars report intensities on different scales (calibration, antenna
gains, processing gains, scattering model). Before pre-training on simulated frames, the paper
matches the simulated intensity distribution to the real one in log space; intensities here are
already logarithmic (dB), so matching in log space is quantile matching of the dB values
(Gonzalez & Woods, *Digital Image Processing*, 4th ed., §3.3.2 "histogram specification"):
each simulated value is replaced by the real-domain value at the same cumulative probability::

    y = F_real^{-1}( F_sim(x) )

with both CDFs taken from ``n_quantiles`` empirical quantiles and linear interpolation between
them; values beyond the fitted range map onto the real extremes. The map is monotone, so the
order of points by intensity (what CFAR and the detector's features see) is kept.

Fit it on the real **training** frames only (never on val/test) and store
:meth:`IntensityMatch.to_dict` in the provenance of whatever it was applied to.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

__all__ = ["IntensityMatch", "fit_intensity_match"]


@dataclasses.dataclass(frozen=True, eq=False)
class IntensityMatch:
    """A monotone map from source (sim) intensities to the target (real) distribution.

    Attributes
    ----------
    source_quantiles_db : (Q,) float64 — source intensities [dB] at the probabilities.
    target_quantiles_db : (Q,) float64 — target intensities [dB] at the same probabilities.
    probabilities : (Q,) float64 — cumulative probabilities in [0, 1].
    n_source, n_target : int — number of values each side was fitted on.
    """

    source_quantiles_db: np.ndarray
    target_quantiles_db: np.ndarray
    probabilities: np.ndarray
    n_source: int
    n_target: int

    def apply(self, intensity_db: np.ndarray) -> np.ndarray:
        """Map source intensities [dB] onto the target distribution; same shape, float32."""
        x = np.asarray(intensity_db, dtype=np.float64)
        src, tgt = self.source_quantiles_db, self.target_quantiles_db
        # the source quantiles may repeat (ties); interpolate on the unique ones, taking the
        # mean probability of each tie so repeated values map to one target value
        uniq, inverse = np.unique(src, return_inverse=True)
        prob = np.bincount(inverse, weights=self.probabilities) / np.bincount(inverse)
        p = np.interp(x, uniq, prob) if len(uniq) > 1 else np.full_like(x, 0.5)
        return np.interp(p, self.probabilities, tgt).astype(np.float32)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (for provenance)."""
        return {
            "method": "log-space histogram matching (quantile map of dB values)",
            "source_quantiles_db": [float(v) for v in self.source_quantiles_db],
            "target_quantiles_db": [float(v) for v in self.target_quantiles_db],
            "probabilities": [float(v) for v in self.probabilities],
            "n_source": int(self.n_source),
            "n_target": int(self.n_target),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> IntensityMatch:
        return cls(np.asarray(d["source_quantiles_db"], np.float64),
                   np.asarray(d["target_quantiles_db"], np.float64),
                   np.asarray(d["probabilities"], np.float64),
                   int(d["n_source"]), int(d["n_target"]))


def fit_intensity_match(
    source_db: np.ndarray, target_db: np.ndarray, n_quantiles: int = 256
) -> IntensityMatch:
    """Fit the quantile map from ``source_db`` (sim) to ``target_db`` (real) intensities.

    Parameters
    ----------
    source_db, target_db : (N,) / (M,) arrays [dB] — pooled point intensities of each domain
        (e.g. every point of every real training frame).
    n_quantiles : int >= 2 — probabilities ``linspace(0, 1, n_quantiles)``.

    Raises
    ------
    ValueError — an empty or non-finite input.
    """
    if int(n_quantiles) < 2:
        raise ValueError(f"n_quantiles must be >= 2, got {n_quantiles}")
    src = np.asarray(source_db, dtype=np.float64).ravel()
    tgt = np.asarray(target_db, dtype=np.float64).ravel()
    for name, v in (("source", src), ("target", tgt)):
        if v.size == 0:
            raise ValueError(f"intensity matching: no {name} intensities to fit on")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"intensity matching: {name} intensities contain NaN or inf")
    prob = np.linspace(0.0, 1.0, int(n_quantiles))
    return IntensityMatch(np.quantile(src, prob), np.quantile(tgt, prob), prob,
                          int(src.size), int(tgt.size))
