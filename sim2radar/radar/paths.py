"""Propagation paths of one radar frame: the tracer's per-path output for signal-level synthesis.

The ray tracer (:meth:`sim2radar.radar.RadarScene.trace_paths`) returns, instead of pre-binned
cells, one entry per (ray, interaction) that sends energy back to the radar: its complex gain,
its total length, where it leaves and re-enters the array (first and last interaction point),
and how fast its length changes when the rig moves. The signal-level simulator
(:mod:`sim2radar.radar.fmcw`) turns each path into IF samples per TX/RX pair using each
element's *own* path length (near field: the 86-element array's far-field distance
``2 D^2 / lambda`` is ~14 m at 77 GHz, beyond most indoor targets)::

    L_{t,r} = |P_dep - tx_t| + inner_length + |P_arr - rx_r|        [m]
    inner_length = path_length - |P_dep| - |P_arr|                    [m]

with ``tx_t`` / ``rx_r`` the element positions in the radar frame and the radar-frame origin at
the array's phase centre (:func:`sim2radar.radar.fmcw.element_positions_m`).

Conventions
-----------
* Radar frame: x forward, y left, z up [m] (as everywhere in :mod:`sim2radar.radar`).
* ``amplitude`` uses the tracer's field normalisation (:mod:`sim2radar.radar.returns`): a
  monostatic point target of RCS ``sigma`` [m^2] at range ``r`` has ``|a|^2 = sigma / (4 pi
  r^4)``; antenna gains, element patterns and transmit power are **not** included (the
  synthesis applies them). The carrier phase ``exp(-j k L)`` is **not** included either (it
  differs per element); reflection / transmission phases and random speckle phases are.
* ``range_rate_mps`` = ``(dL/dt) / 2`` for the rig's velocity [m/s] (positive = the path gets
  longer, target receding); the Doppler shift is ``f_D = -2 range_rate / lambda``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

__all__ = ["PathSet", "PATH_KINDS"]

#: Codes of :attr:`PathSet.kind`: how the path's last interaction sends energy back.
PATH_KINDS: dict[str, int] = {"specular": 0, "diffuse": 1, "mixed": 2}


@dataclasses.dataclass(frozen=True, eq=False)
class PathSet:
    """P propagation paths from the radar back to the radar, radar frame.

    Attributes
    ----------
    amplitude : (P,) complex128 — complex path gain [sim. field units, see module doc],
        without the carrier phase ``exp(-j k L)``.
    path_length_m : (P,) float64 — total round-trip length ``L`` from the array phase centre
        through every interaction and back [m]; delay ``tau = L / c`` [s].
    departure_point_m : (P, 3) float64 — first interaction point [m].
    arrival_point_m : (P, 3) float64 — last interaction point [m] (equal to the departure point
        for single-interaction paths).
    range_rate_mps : (P,) float64 — half the rate of change of ``L`` [m/s] (0 for a static rig).
    n_interactions : (P,) int8 — reflections / scatterings / transmissions along the path (>= 1).
    kind : (P,) int8 — :data:`PATH_KINDS` code of the last interaction.
    stats : dict — tracer counters and timings (``n_rays``, ``hits_per_bounce``, ``seconds``).
    """

    amplitude: np.ndarray
    path_length_m: np.ndarray
    departure_point_m: np.ndarray
    arrival_point_m: np.ndarray
    range_rate_mps: np.ndarray
    n_interactions: np.ndarray
    kind: np.ndarray
    stats: dict[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        p = len(self.amplitude)
        for name in ("path_length_m", "range_rate_mps", "n_interactions", "kind"):
            if len(getattr(self, name)) != p:
                raise ValueError(f"PathSet.{name} has {len(getattr(self, name))} entries, "
                                 f"amplitude has {p}")
        for name in ("departure_point_m", "arrival_point_m"):
            if np.shape(getattr(self, name)) != (p, 3):
                raise ValueError(f"PathSet.{name} must be ({p}, 3), got "
                                 f"{np.shape(getattr(self, name))}")

    def __len__(self) -> int:
        return int(len(self.amplitude))

    @property
    def inner_length_m(self) -> np.ndarray:
        """(P,) float64 — path length between the first and last interaction [m]."""
        return (self.path_length_m - np.linalg.norm(self.departure_point_m, axis=1)
                - np.linalg.norm(self.arrival_point_m, axis=1))

    @property
    def range_m(self) -> np.ndarray:
        """(P,) float64 — apparent range ``L / 2`` [m]."""
        return 0.5 * self.path_length_m

    def select(self, mask: np.ndarray) -> PathSet:
        """The paths where ``mask`` is true (or at the given indices)."""
        return PathSet(
            self.amplitude[mask], self.path_length_m[mask], self.departure_point_m[mask],
            self.arrival_point_m[mask], self.range_rate_mps[mask], self.n_interactions[mask],
            self.kind[mask], dict(self.stats),
        )

    def merged(self, voxel_m: float, wavelength_m: float) -> PathSet:
        """Paths sharing a departure voxel, an arrival voxel and an interaction count, each
        group summed coherently into one path.

        Voxels are cubes of side ``voxel_m`` on a grid fixed in the radar frame. Per group
        (weights ``w_i = |a_i|^2``, uniform where all are zero)::

            L_m = sum w_i L_i / sum w_i                         merged length [m]
            A   = sum a_i exp(-j k (L_i - L_m))                 merged amplitude, k = 2 pi / lambda
            P_dep, P_arr, range rate = w-weighted means

        Approximation: ``A e^{-j k L_m}`` is the exact coherent sum at the array's phase centre
        and the carrier frequency. An element at offset ``p`` from the phase centre sees each
        merged path with a phase error ``~ k (u_i - u_m) . p`` per leg, ``|u_i - u_m| <=
        sqrt(3) voxel_m / r`` (r: range of the voxel), i.e. at most ``k sqrt(3) voxel_m
        |p| / r`` [rad] per leg (0.24 rad at voxel 5 mm, |p| 5 cm, r 2 m); off the carrier the
        residual delay ``|L_i - L_m| <= 2 sqrt(3) voxel_m`` shifts the range response by a
        fraction ``sqrt(3) voxel_m / dR`` of a range bin. Keep ``voxel_m`` well below the
        range resolution and ``lambda r / (k |p|)``.

        Parameters
        ----------
        voxel_m : float — voxel side [m], > 0.
        wavelength_m : float — carrier wavelength [m] (the phase correction).

        Returns
        -------
        PathSet — ``stats`` gains ``n_paths_before_merge`` and ``merge_voxel_m``.
        """
        v = float(voxel_m)
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"voxel_m must be > 0 [m], got {voxel_m}")
        p = len(self)
        stats = dict(self.stats)
        stats["n_paths_before_merge"] = p
        stats["merge_voxel_m"] = v
        if p == 0:
            return dataclasses.replace(self, stats=stats)
        key = np.concatenate(
            [
                self.n_interactions.astype(np.int64)[:, None],
                np.floor(self.departure_point_m / v).astype(np.int64),
                np.floor(self.arrival_point_m / v).astype(np.int64),
            ],
            axis=1,
        )
        _, inv = np.unique(key, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        g = int(inv.max()) + 1
        w = np.abs(self.amplitude) ** 2
        wsum = np.bincount(inv, weights=w, minlength=g)
        empty = wsum <= 0
        if np.any(empty):
            w = np.where(empty[inv], 1.0, w)
            wsum = np.bincount(inv, weights=w, minlength=g)

        def mean(x: np.ndarray) -> np.ndarray:
            return np.bincount(inv, weights=w * x, minlength=g) / wsum

        length = mean(self.path_length_m)
        k = 2.0 * np.pi / float(wavelength_m)
        shifted = self.amplitude * np.exp(-1j * k * (self.path_length_m - length[inv]))
        amp = (np.bincount(inv, weights=shifted.real, minlength=g)
               + 1j * np.bincount(inv, weights=shifted.imag, minlength=g))
        dep = np.stack([mean(self.departure_point_m[:, i]) for i in range(3)], axis=1)
        arr = np.stack([mean(self.arrival_point_m[:, i]) for i in range(3)], axis=1)
        k_min = np.full(g, np.iinfo(np.int8).max, dtype=np.int8)
        k_max = np.full(g, np.iinfo(np.int8).min, dtype=np.int8)
        np.minimum.at(k_min, inv, self.kind)
        np.maximum.at(k_max, inv, self.kind)
        n_int = np.zeros(g, dtype=np.int8)
        n_int[inv] = self.n_interactions
        return PathSet(
            amplitude=amp.astype(np.complex128),
            path_length_m=length,
            departure_point_m=dep,
            arrival_point_m=arr,
            range_rate_mps=mean(self.range_rate_mps),
            n_interactions=n_int,
            kind=np.where(k_min == k_max, k_min, PATH_KINDS["mixed"]).astype(np.int8),
            stats=stats,
        )

    @classmethod
    def point_targets(
        cls,
        positions_m: np.ndarray,
        rcs_m2: np.ndarray | float = 1.0,
        range_rate_mps: np.ndarray | float = 0.0,
        phase_rad: np.ndarray | float = 0.0,
    ) -> PathSet:
        """Ideal monostatic point scatterers (for tests and calibration).

        Parameters
        ----------
        positions_m : (P, 3) — target positions, radar frame [m].
        rcs_m2 : (P,) or scalar — radar cross section [m^2].
        range_rate_mps : (P,) or scalar — radial velocity [m/s] (positive = receding).
        phase_rad : (P,) or scalar — extra scattering phase [rad].
        """
        pos = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
        p = len(pos)
        r = np.linalg.norm(pos, axis=1)
        if np.any(r <= 0):
            raise ValueError("point targets must not sit at the radar's origin")
        sigma = np.broadcast_to(np.asarray(rcs_m2, dtype=np.float64), (p,))
        amp = np.sqrt(sigma / (4.0 * np.pi)) / r**2  # |a|^2 = sigma / (4 pi r^4)
        amp = amp * np.exp(1j * np.broadcast_to(np.asarray(phase_rad, np.float64), (p,)))
        return cls(
            amplitude=amp.astype(np.complex128),
            path_length_m=2.0 * r,
            departure_point_m=pos.copy(),
            arrival_point_m=pos.copy(),
            range_rate_mps=np.broadcast_to(np.asarray(range_rate_mps, np.float64), (p,)).copy(),
            n_interactions=np.ones(p, np.int8),
            kind=np.full(p, PATH_KINDS["diffuse"], np.int8),
        )

    @classmethod
    def concatenate(cls, sets: list[PathSet]) -> PathSet:
        """One path set from several (stats of the first)."""
        if not sets:
            raise ValueError("nothing to concatenate")
        return cls(
            np.concatenate([s.amplitude for s in sets]),
            np.concatenate([s.path_length_m for s in sets]),
            np.concatenate([s.departure_point_m for s in sets]),
            np.concatenate([s.arrival_point_m for s in sets]),
            np.concatenate([s.range_rate_mps for s in sets]),
            np.concatenate([s.n_interactions for s in sets]),
            np.concatenate([s.kind for s in sets]),
            dict(sets[0].stats),
        )
