"""Range bins and the virtual array's angle response (NumPy side of the binning simulator).

The radar resolves range with the range FFT (bins ``i * dR``) and angle with its MIMO virtual
array; this module turns the tracer's per-ray contributions into what that array measures.

Model
-----
A contribution ``k`` (complex amplitude ``a_k`` with carrier phase, range ``r_k``, arrival
direction cosines ``u_a = cos(el) sin(az)``, ``u_e = sin(el)`` of its last interaction point)
lands in range bin ``i = round(r_k / dR) mod N`` (``N`` bins over ``[0, R_max)``, scaled by the
receiver's IF response of its true bin, :func:`sim2radar.radar.receiver.range_bin_gain`: the
anti-alias roll-off over the last tenth of the range axis, and a path beyond ``R_max``
aliased, attenuated) and reaches virtual element ``n`` at
``(x_n, z_n)`` [lambda/2] with the plane-wave phase ``e^{j pi (x_n u_a + z_n u_e)}`` (far field
of each scatterer; monostatic virtual-array model: TX + RX position, one direction). Element
positions are measured from the virtual array's centroid, the radar frame's origin from which
the tracer measures path lengths (the array's phase centre). The channel signal of range bin
``i`` is::

    s(x, z)[i] = sum_{k in i} a_k e^{j pi (x u_a,k + z u_e,k)}

and the beams are those of TI's cascade angle processing (``DOA_beamformingFFT_2D`` of the
mmWave Studio cascade MATLAB chain): one channel per distinct position (duplicates of the
MIMO virtual array dropped), uniform weights, conventional (Bartlett/FFT) beamforming::

    A[i](u_a)      = (1 / n_0) sum_{x in row 0} s(x, z_0) e^{-j pi x u_a}      (azimuth map)
    B[i](u_a, u_e) = (1 / n)   sum_{(x, z)}     s(x, z) e^{-j pi (x u_a + z u_e)}  (2D beam)

``A`` uses the complete azimuth row (the row with most positions; detection runs on it),
``B`` every distinct position (the returned cube; elevation is read from it at the detected
azimuth). One scatterer reads ``A = B = a_k`` in its own direction with the array factor
around it, two scatterers closer than the beamwidth merge into one peak, and a surface's
contributions add up as the array sums them (its physical-optics integral is not cut into
angle bins). Beams are sampled on bins uniform in ``u`` (:attr:`RadarConfig.azimuth_bins_u`),
one on boresight, width = the array's resolution. (Weighting all ``N`` channels instead would
be the matched filter, but on the cascade's partly filled rows it raises the first azimuth
sidelobe from -13 to -9 dB.)

(The per-frame NumPy steps avoid BLAS: its worker threads and Dr.Jit's contend for the cores
and turn a 0.1 ms matrix product into ~10 ms; FFTs, a chirp-z transform and einsum do the work.
Only the 2D cube, formed on request, is one matrix product.)

Fast evaluation (the Dr.Jit tracer deposits; :func:`deposit` is its NumPy twin): per distinct
element row ``z_j`` the contributions are summed on a fine grid of ``M`` points in ``u_a``
over [-1, 1) (nearest point ``u_g``, ``M >= 4 x`` the azimuth span [lambda/2]), with the exact
elevation phase and a fixed phase ramp that lets an FFT do the azimuth sum (``n = x + x_shift``
are integers for a regular array)::

    G[j, i, g] += a_k e^{j pi z_j u_e,k} e^{-j pi x_shift u_g}
    s(x, z_j) = sum_g G[j, i, g] e^{j pi n u_g} = M e^{-j pi n} IFFT_M(G[j, i, :])[n]

The phase error at element ``x`` is ``pi |x| |u_a - u_g| <= pi span / (2 M) <= pi / 8`` (``x``
from the centroid), i.e. a pointing error of at most ``1 / M`` in ``u`` (0.11 deg for
M = 512); contributions within ``1 / M`` of ``u_a = 1`` (90 deg) wrap to ``u_g = -1``.

Approximations: each scatterer is a plane wave across the array (the array's near-field
curvature, ~1 rad at 3 m for the cascade, is not modelled); a multi-bounce return whose first
and last interaction points differ is placed at its arrival direction (the virtual-array
model has one direction per return; the signal-level reference radar treats the TX and RX
legs exactly).

Receiver noise (:func:`add_receiver_noise`): ``N0`` (link budget) is the noise of the matched
filter over all ``N`` channels, i.e. ``N N0`` per channel; one channel per position leaves
``N N0 / n`` per beam (3.5 dB above ``N0`` for the cascade's 86-position azimuth row).

Point positions (:mod:`sim2radar.radar.detection`) come from the beam response itself (peak
interpolation), ranges from the power-weighted mean range of the contributions in the
detected range bin near the peak's beam — a sub-bin range estimate in place of range-FFT peak
interpolation (error <= dR / 2; hard range bins, no range sidelobes).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from sim2radar.hardware import one_blas_thread
from sim2radar.radar.config import RadarConfig

__all__ = [
    "Accumulator",
    "ArrayGeometry",
    "TraceResult",
    "RowNoise",
    "accumulate",
    "add_receiver_noise",
    "array_geometry",
    "azimuth_map",
    "azimuth_response",
    "beam_response",
    "beamform",
    "bin_indices",
    "deposit",
    "direction_cosines",
    "fine_grid_index",
    "integrated_power",
    "row_noise",
]

#: Fine-grid points per lambda/2 of azimuth span (phase error <= pi / (2 * this)).
FINE_GRID_OVERSAMPLING = 4


@dataclasses.dataclass(frozen=True, eq=False)
class ArrayGeometry:
    """The virtual array grouped for beamforming, plus the cube's angle bins.

    Attributes
    ----------
    x_half_wl : (n_x,) float64 — distinct azimuth positions [lambda/2] from the centroid,
        ascending.
    z_half_wl : (n_z,) float64 — distinct elevation positions (rows) [lambda/2] from the
        centroid, ascending.
    count : (n_z, n_x) int64 — virtual elements at each (row, azimuth position).
    n_elements : int — virtual channels N.
    main_row : int — index of the complete azimuth row (most positions; ties: lowest z).
    x_shift : float — ``x_half_wl + x_shift`` are the TI-style positions minus their minimum
        (integers for a regular array: the fine grid then uses an FFT).
    fine_az : int — fine-grid points M over u_a in [-1, 1).
    u_az, u_el : (n_a,), (n_e,) float64 — beam (bin) centres in direction cosines [-].
    """

    x_half_wl: np.ndarray
    z_half_wl: np.ndarray
    count: np.ndarray
    n_elements: int
    main_row: int
    x_shift: float
    fine_az: int
    u_az: np.ndarray
    u_el: np.ndarray

    @property
    def present(self) -> np.ndarray:
        """(n_z, n_x) bool — positions holding at least one virtual element."""
        return self.count > 0

    @property
    def weight(self) -> np.ndarray:
        """(n_z, n_x) float64 — 2D beam weights: ``1 / n`` at each of the ``n`` positions."""
        return self.present / float(self.present.sum())

    @property
    def main_weight(self) -> np.ndarray:
        """(n_x,) float64 — azimuth-map weights: ``1 / n_0`` on the main row's positions."""
        row = self.present[self.main_row]
        return row / float(row.sum())

    @property
    def noise_factor(self) -> float:
        """Beam noise of :func:`beamform` over ``N0`` [-]: ``N / n`` (one channel per position)."""
        return self.n_elements / float(self.present.sum())

    @property
    def main_noise_factor(self) -> float:
        """Beam noise of :func:`azimuth_map` over ``N0`` [-]: ``N / n_0``."""
        return self.n_elements / float(self.present[self.main_row].sum())

    @property
    def fine_u(self) -> np.ndarray:
        """(M,) float64 — fine-grid points ``u_g = -1 + 2 g / M``."""
        return -1.0 + 2.0 * np.arange(self.fine_az) / self.fine_az

    @property
    def integer_x(self) -> bool:
        """Whether the shifted azimuth positions are integers (the fine grid then uses an FFT)."""
        x = self.x_half_wl + self.x_shift
        return bool(np.allclose(x, np.round(x), atol=1e-6))

    @functools.cached_property
    def bin_steering(self) -> np.ndarray:
        """(n_z * n_x, n_a * n_e) complex64 — :meth:`steering` on the bin centres (cached)."""
        return self.steering(self.u_az, self.u_el).astype(np.complex64)

    @functools.cached_property
    def _main_czt(self) -> tuple[object, np.ndarray, np.ndarray]:
        """Chirp-z transform evaluating the main row's beam on the azimuth bins (integer
        positions ``n = x + x_shift``): ``(czt, n of the main row's positions, post-phase)``."""
        n = np.round(self.x_half_wl + self.x_shift).astype(np.int64)
        span = int(n.max()) + 1
        du = float(self.u_az[1] - self.u_az[0]) if len(self.u_az) > 1 else 1.0
        import scipy.signal  # imported here: ~0.5 s, only needed once a scene is traced

        czt = scipy.signal.CZT(span, len(self.u_az), w=np.exp(-1j * math.pi * du),
                               a=np.exp(1j * math.pi * float(self.u_az[0])))
        post = np.exp(1j * math.pi * self.x_shift * self.u_az)  # e^{-j pi (n - shift) u}
        return czt, n, post

    @functools.cached_property
    def fine_phases(self) -> np.ndarray:
        """(M, n_x) complex128 — ``e^{j pi u_g (x + x_shift)}``: the channel signal at
        position ``x`` is ``sum_g G[g]`` times this (:meth:`Accumulator.aperture`; an FFT
        evaluates the same sum when the shifted positions are integers)."""
        return np.exp(1j * math.pi * np.outer(self.fine_u, self.x_half_wl + self.x_shift))

    @functools.cached_property
    def _fft_terms(self) -> tuple[np.ndarray, np.ndarray]:
        """Column indices ``n`` (n_x,) and post-phase ``M e^{-j pi n}`` (n_x,) of the FFT."""
        n = np.round(self.x_half_wl + self.x_shift).astype(np.int64)
        return n, self.fine_az * np.exp(-1j * math.pi * n)

    def steering(self, u_az: np.ndarray, u_el: np.ndarray) -> np.ndarray:
        """(n_z * n_x, len(u_az) * len(u_el)) complex128 — ``w_{z,x} e^{-j pi (x u_a + z u_e)}``
        for every (row, position) and (azimuth, elevation) pair (azimuth-major columns)."""
        ex = np.exp(-1j * math.pi * np.outer(self.x_half_wl, u_az))  # (n_x, P)
        ez = np.exp(-1j * math.pi * np.outer(self.z_half_wl, u_el))  # (n_z, Q)
        w = self.weight[:, :, None, None] * ez[:, None, None, :] * ex[None, :, :, None]
        return w.reshape(len(self.z_half_wl) * len(self.x_half_wl), len(u_az) * len(u_el))


_GEOMETRY_CACHE: dict[str, ArrayGeometry] = {}
_GEOMETRY_BY_ID: dict[int, tuple[RadarConfig, ArrayGeometry]] = {}


def array_geometry(radar: RadarConfig) -> ArrayGeometry:
    """The :class:`ArrayGeometry` of ``radar`` (cached per config object and content)."""
    hit = _GEOMETRY_BY_ID.get(id(radar))
    if hit is not None and hit[0] is radar:
        return hit[1]
    geom = _array_geometry(radar)
    if len(_GEOMETRY_BY_ID) > 32:
        _GEOMETRY_BY_ID.pop(next(iter(_GEOMETRY_BY_ID)))
    _GEOMETRY_BY_ID[id(radar)] = (radar, geom)
    return geom


def _array_geometry(radar: RadarConfig) -> ArrayGeometry:
    key = radar.content_hash()
    if key in _GEOMETRY_CACHE:
        return _GEOMETRY_CACHE[key]
    virt = np.round(np.asarray(radar.virtual_array_half_wl, dtype=np.float64), 6)
    xs = np.unique(virt[:, 0])
    zs = np.unique(virt[:, 1])
    count = np.zeros((len(zs), len(xs)), dtype=np.int64)
    np.add.at(count, (np.searchsorted(zs, virt[:, 1]), np.searchsorted(xs, virt[:, 0])), 1)
    span = float(xs.max() - xs.min()) + 1.0
    fine = max(64, 1 << math.ceil(math.log2(FINE_GRID_OVERSAMPLING * span)))
    x_c, z_c = float(virt[:, 0].mean()), float(virt[:, 1].mean())
    geom = ArrayGeometry(
        x_half_wl=xs - x_c,
        z_half_wl=zs - z_c,
        count=count,
        n_elements=int(len(virt)),
        main_row=int(np.argmax((count > 0).sum(axis=1))),
        x_shift=x_c - float(xs.min()),
        fine_az=int(fine),
        u_az=radar.azimuth_bins_u,
        u_el=radar.elevation_bins_u,
    )
    if len(_GEOMETRY_CACHE) > 16:
        _GEOMETRY_CACHE.pop(next(iter(_GEOMETRY_CACHE)))
    _GEOMETRY_CACHE[key] = geom
    return geom


def direction_cosines(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Range [m] and direction cosines ``u_a = q_y / |q|``, ``u_e = q_z / |q|`` of radar-frame
    points ``q`` (N, 3) [m]."""
    q = np.asarray(q, dtype=np.float64)
    r = np.linalg.norm(q, axis=1)
    safe = np.maximum(r, 1e-12)
    return r, q[:, 1] / safe, q[:, 2] / safe


@dataclasses.dataclass(frozen=True, eq=False)
class Accumulator:
    """The binning simulator's per-frame sums.

    Attributes
    ----------
    grid : (n_z, n_range, M) complex — contributions summed per element row, range bin and
        fine azimuth point, with the phases of the module doc [sim. amplitude].
    power : (n_range * n_az * n_el,) float64 — ``sum |a|^2`` per (range bin, nearest beam) cell.
    range_w : (n_range * n_az * n_el,) float64 — ``sum |a|^2 r`` per cell [m].
    """

    grid: np.ndarray
    power: np.ndarray
    range_w: np.ndarray

    def aperture(self, geometry: ArrayGeometry, fine_mask: np.ndarray | None = None
                 ) -> np.ndarray:
        """(n_range, n_z, n_x) complex — the channel signal ``s(x, z)`` per range bin and
        distinct position (complex64 for a complex64 grid); with ``fine_mask`` ((M,) bool),
        only of the contributions on those fine azimuth points (one Doppler slab,
        :func:`sim2radar.radar.detection.doppler_bins`)."""
        g = np.asarray(self.grid)
        if fine_mask is not None and not np.all(fine_mask):  # (all points: the same values)
            g = g * np.asarray(fine_mask, dtype=bool)[None, None, :]
        if geometry.integer_x:
            # sum_g G[g] e^{j pi n (-1 + 2g/M)} = e^{-j pi n} M ifft(G)[n]
            import scipy.fft  # imported here: ~0.2 s, only needed once a scene is traced

            n, post = geometry._fft_terms
            s = scipy.fft.ifft(g, axis=-1)[..., n] * post.astype(g.dtype)
        else:
            s = np.einsum("zrg,gx->zrx", g, geometry.fine_phases, optimize=False)
        return np.transpose(s, (1, 0, 2))

    def slab_apertures(self, geometry: ArrayGeometry, labels: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """The channel signal of each group of fine azimuth points (one Doppler slab each,
        :func:`sim2radar.radar.detection.doppler_bins`): ``(slabs, s)`` with ``slabs`` the
        sorted distinct ``labels`` ((M,) int) and ``s`` (S, n_range, n_z, n_x) complex64,
        ``s[k]`` = :meth:`aperture` of the points labelled ``slabs[k]``.

        Each slab is one product of its own points' columns of the grid with the fine-grid
        phases ``e^{j pi u_g (x + x_shift)}`` (the sum the FFT of :meth:`aperture` evaluates
        for all points at once): S slabs cost one dense transform in all, not S FFTs.
        """
        g = np.asarray(self.grid)
        n_z, n_r, m = g.shape
        labels = np.asarray(labels).reshape(-1)
        if len(labels) != m:
            raise ValueError(f"labels: {len(labels)} fine points, the grid has {m}")
        slabs, inverse = np.unique(labels, return_inverse=True)
        if len(slabs) == 1:                 # every point: the FFT of aperture()
            return slabs, self.aperture(geometry)[None]
        e = geometry.fine_phases.astype(np.complex64)                       # (M, n_x)
        out = np.empty((len(slabs), n_r, n_z, len(geometry.x_half_wl)), dtype=np.complex64)
        flat = g.reshape(n_z * n_r, m)
        with one_blas_thread():
            for k in range(len(slabs)):
                cols = np.flatnonzero(inverse == k)
                s = (flat[:, cols] @ e[cols]).reshape(n_z, n_r, -1)
                out[k] = np.transpose(s, (1, 0, 2))
        return slabs, out


@dataclasses.dataclass(frozen=True)
class TraceResult:
    """Accumulated returns of one frame plus counters and timings (what
    :meth:`sim2radar.radar.RadarScene.trace` returns).

    Attributes
    ----------
    accumulator : Accumulator — the frame's sums.
    n_rays : int — rays traced.
    hits_per_bounce : tuple of int — rays that hit a surface, per bounce.
    seconds : dict — wall time per tracing step [s] (``rays``, ``trace``, ``readback``).
    """

    accumulator: Accumulator
    n_rays: int
    hits_per_bounce: tuple[int, ...]
    seconds: dict[str, float]


def fine_grid_index(u_az: np.ndarray, geometry: ArrayGeometry) -> tuple[np.ndarray, np.ndarray]:
    """Nearest fine-grid point of each ``u_a``: index ``g`` in [0, M) and ``u_a - u_g`` [-]."""
    m = geometry.fine_az
    gu = np.floor((np.asarray(u_az, dtype=np.float64) + 1.0) * (m / 2.0) + 0.5)
    delta = np.asarray(u_az) - (-1.0 + 2.0 * gu / m)
    return np.mod(gu, m).astype(np.int64), delta


def bin_indices(
    range_m: np.ndarray, u_az: np.ndarray, u_el: np.ndarray, radar: RadarConfig
) -> np.ndarray:
    """Flat (range bin, nearest beam) cell index of each contribution, ``-1`` outside the cube.

    Parameters
    ----------
    range_m : (N,) [m]
    u_az, u_el : (N,) direction cosines [-]

    Returns
    -------
    (N,) int64
    """
    n_r, n_a, n_e = radar.n_range_bins, radar.n_azimuth_bins, radar.n_elevation_bins
    ir = np.floor(np.asarray(range_m) / radar.range_resolution_m + 0.5).astype(np.int64)
    ia = np.floor(np.asarray(u_az) / radar.azimuth_bin_u + 0.5).astype(np.int64) + n_a // 2
    ie = np.floor(np.asarray(u_el) / radar.elevation_bin_u + 0.5).astype(np.int64) + n_e // 2
    ok = (ir >= 0) & (ir < n_r) & (ia >= 0) & (ia < n_a) & (ie >= 0) & (ie < n_e)
    return np.where(ok, (ir * n_a + ia) * n_e + ie, -1)


def deposit(
    range_m: np.ndarray,
    u_az: np.ndarray,
    u_el: np.ndarray,
    amplitude: np.ndarray,
    radar: RadarConfig,
) -> Accumulator:
    """Sum contributions into an :class:`Accumulator` (NumPy twin of the Dr.Jit deposit).

    Parameters
    ----------
    range_m : (N,) float [m] — half the path length (the true range: the receiver's IF
        response of its bin applies, and a range beyond ``R_max`` is seen modulo ``R_max``,
        :mod:`sim2radar.radar.receiver`).
    u_az, u_el : (N,) float [-] — arrival direction cosines (radar frame).
    amplitude : (N,) complex — with carrier phase [sim. amplitude], before the IF response;
        zero = dropped.

    Returns
    -------
    Accumulator
    """
    from sim2radar.radar.receiver import range_bin_gain

    geom = array_geometry(radar)
    n_r = radar.n_range_bins
    ir_true = np.floor(np.asarray(range_m) / radar.range_resolution_m + 0.5).astype(np.int64)
    gain = range_bin_gain(radar)
    a = np.asarray(amplitude, dtype=np.complex128) * gain[np.clip(ir_true, 0, len(gain) - 1)]
    # complex sampling: a return beyond R_max is seen in bin (true bin mod N), attenuated
    wraps = np.floor_divide(ir_true, n_r)
    ir = ir_true - wraps * n_r
    range_m = np.asarray(range_m, dtype=np.float64) - wraps * (n_r * radar.range_resolution_m)
    ok = (ir_true >= 0) & (a != 0)
    g, _ = fine_grid_index(u_az, geom)
    u_g = geom.fine_u[g]
    grid = np.zeros((len(geom.z_half_wl), n_r, geom.fine_az), dtype=np.complex128)
    for j, z in enumerate(geom.z_half_wl):
        v = a * np.exp(1j * math.pi * (z * np.asarray(u_el) - geom.x_shift * u_g))
        np.add.at(grid[j], (ir[ok], g[ok]), v[ok])
    idx = bin_indices(range_m, u_az, u_el, radar)
    idx = np.where(a != 0, idx, -1)
    power, range_w = accumulate(idx, a, range_m, radar)
    return Accumulator(grid=grid, power=power, range_w=range_w)


def accumulate(
    index: np.ndarray, amplitude: np.ndarray, range_m: np.ndarray, radar: RadarConfig
) -> tuple[np.ndarray, np.ndarray]:
    """``sum |a|^2`` and ``sum |a|^2 r`` per cell ``index`` (``-1`` = dropped).

    Returns
    -------
    power, range_w : (n_cells,) float64
    """
    n_cells = radar.n_range_bins * radar.n_azimuth_bins * radar.n_elevation_bins
    ok = np.asarray(index) >= 0
    idx = np.asarray(index)[ok]
    p = np.abs(np.asarray(amplitude)[ok]) ** 2
    power = np.bincount(idx, weights=p, minlength=n_cells).astype(np.float64)
    range_w = np.bincount(idx, weights=p * np.asarray(range_m)[ok], minlength=n_cells)
    return power, range_w.astype(np.float64)


def add_receiver_noise(
    aperture: np.ndarray, geometry: ArrayGeometry, noise_power: float, rng: np.random.Generator
) -> np.ndarray:
    """The channel signal plus receiver noise: circular complex Gaussian, independent per
    position, variance ``N * noise_power`` (one virtual channel of a receiver whose
    all-channel matched filter has ``noise_power`` per cell, see module doc).

    Parameters
    ----------
    aperture : (n_range, n_z, n_x) complex — from :meth:`Accumulator.aperture`.
    noise_power : float — ``N0`` [sim. |a|^2] (:func:`sim2radar.radar.detection.cell_noise_power`).
    """
    sigma = np.where(geometry.present, math.sqrt(geometry.n_elements * noise_power / 2.0), 0.0)
    shape = aperture.shape
    # sigma (re + j im), real parts drawn first, added in place (no complex temporaries)
    re, im = rng.standard_normal(shape), rng.standard_normal(shape)
    out = np.asarray(aperture).astype(np.complex128)
    re *= sigma
    im *= sigma
    out.real += re
    out.imag += im
    return out


@dataclasses.dataclass(frozen=True)
class RowNoise:
    """Receiver noise of channel-signal rows, drawn in two steps (:func:`integrated_power`):
    first what the channel-integrated power needs, then the rest of the noise of the rows
    that are looked at (:func:`row_noise`).

    Attributes
    ----------
    parallel : (...) complex128 — each row's noise component along its own signal vector
        (any fixed direction for a row without signal) [sqrt(sim. |a|^2)].
    rest : (...) float64 — the power of the noise orthogonal to it [sim. |a|^2].
    """

    parallel: np.ndarray
    rest: np.ndarray


def integrated_power(signal_power: np.ndarray, n_channels: int, variance: float,
                     rng: np.random.Generator) -> tuple[np.ndarray, RowNoise]:
    """``sum_c |s_c + n_c|^2`` over the ``n_channels`` channels of rows whose signal power is
    ``signal_power`` (...) ``= sum_c |s_c|^2``, with ``n`` circular complex Gaussian noise of
    ``variance`` per channel, independent per channel — drawn without drawing the noise
    samples of every row.

    Along the row's unit signal vector ``e = s / |s|`` the noise is ``n_par ~ CN(0,
    variance)``; orthogonal to it, its power ``Q`` is ``variance * Gamma(C - 1, 1)``, and its
    direction is uniform and independent of ``Q`` (a Gaussian vector's length and direction are
    independent). So ``sum |s + n|^2 = ||s| + n_par|^2 + Q`` exactly: three numbers per row, not
    2C. :func:`row_noise` draws the rest of a row's noise consistent with its draw here
    (tested against the full draw in ``tests/radar/test_detection.py``).

    Returns ``(power (...) float64, RowNoise)``.
    """
    a = np.sqrt(np.asarray(signal_power, dtype=np.float64))
    shape = a.shape
    z = rng.standard_normal((2, *shape)) * math.sqrt(variance / 2.0)
    rest = (rng.gamma(n_channels - 1, variance, size=shape) if n_channels > 1
            else np.zeros(shape))
    power = (a + z[0]) ** 2 + z[1] ** 2 + rest
    return power, RowNoise(z[0] + 1j * z[1], rest)


def row_noise(signal: np.ndarray, drawn: RowNoise, rng: np.random.Generator) -> np.ndarray:
    """(K, C) complex128 — the whole noise of K rows whose ``signal`` (K, C) had its
    integrated power drawn by :func:`integrated_power` (``drawn``: those rows' entries): the
    drawn component along each row's signal plus ``sqrt(rest)`` times a uniform unit vector
    orthogonal to it. ``sum |signal + noise|^2`` is the power drawn there, and the noise is
    distributed as C independent ``CN(0, variance)`` samples."""
    v = np.asarray(signal, dtype=np.complex128)
    k, n_ch = v.shape
    a = np.linalg.norm(v, axis=1)
    e = np.zeros_like(v)
    e[:, 0] = 1.0                                   # a row without signal: any direction
    has = a > 0
    e[has] = v[has] / a[has, None]
    g = rng.standard_normal((k, n_ch)) + 1j * rng.standard_normal((k, n_ch))
    g -= e * np.sum(e.conj() * g, axis=1, keepdims=True)
    norm = np.linalg.norm(g, axis=1, keepdims=True)
    u = np.divide(g, norm, out=np.zeros_like(g), where=norm > 0)
    return drawn.parallel[:, None] * e + np.sqrt(drawn.rest)[:, None] * u


def beamform(aperture: np.ndarray, geometry: ArrayGeometry) -> np.ndarray:
    """(n_range, n_az, n_el) complex64 — the 2D beam ``B[i](u_a, u_e)`` on the bin centres.

    Parameters
    ----------
    aperture : (n_range, n_z, n_x) complex — channel signal per range bin.
    """
    n_r = aperture.shape[0]
    flat = aperture.reshape(n_r, -1).astype(np.complex64)
    return (flat @ geometry.bin_steering).reshape(n_r, len(geometry.u_az), len(geometry.u_el))


def azimuth_map(aperture: np.ndarray, geometry: ArrayGeometry) -> np.ndarray:
    """(n_range, n_az) complex64 — the main row's azimuth beam ``A[i](u_a)`` on the bin centres.

    Parameters
    ----------
    aperture : (n_range, n_z, n_x) complex — channel signal per range bin.
    """
    main = aperture[:, geometry.main_row, :] * geometry.main_weight[None].astype(np.float32)
    if geometry.integer_x and len(geometry.u_az) > 1:
        czt, n, post = geometry._main_czt
        dense = np.zeros((aperture.shape[0], int(n.max()) + 1), dtype=np.complex64)
        dense[:, n] = main
        return (czt(dense, axis=-1) * post[None]).astype(np.complex64)
    steer = np.exp(-1j * math.pi * np.outer(geometry.x_half_wl, geometry.u_az))
    return np.einsum("rx,xa->ra", main, steer, optimize=False).astype(np.complex64)


def azimuth_response(
    aperture_rows: np.ndarray,
    geometry: ArrayGeometry,
    u_az: np.ndarray,
    offsets: np.ndarray | None = None,
) -> np.ndarray:
    """The azimuth beam ``A`` of K range bins at ``u_az[k] + offsets[p]``.

    Parameters
    ----------
    aperture_rows : (K, n_z, n_x) complex — channel signal of each range bin.
    u_az : (K,) float [-] — one direction per range bin.
    offsets : (P,) float [-], optional — offsets from ``u_az`` (default: none, P = 1).

    Returns
    -------
    (K, P) complex128
    """
    off = np.zeros(1) if offsets is None else np.asarray(offsets, dtype=np.float64)
    x = geometry.x_half_wl
    main = geometry.main_weight[None] * aperture_rows[:, geometry.main_row, :]  # (K, n_x)
    main = main * np.exp(-1j * math.pi * np.asarray(u_az, dtype=np.float64)[:, None] * x[None])
    return np.einsum("kx,xp->kp", main, np.exp(-1j * math.pi * np.outer(x, off)), optimize=False)


def beam_response(
    aperture_rows: np.ndarray, geometry: ArrayGeometry, u_az: np.ndarray, u_el: np.ndarray
) -> np.ndarray:
    """The 2D beam ``B`` of K range bins at azimuth ``u_az[k]`` and each elevation ``u_el[q]``.

    Parameters
    ----------
    aperture_rows : (K, n_z, n_x) complex — channel signal of each range bin.
    u_az : (K,) float [-]; u_el : (Q,) float [-].

    Returns
    -------
    (K, Q) complex128
    """
    w = geometry.weight[None] * aperture_rows  # (K, n_z, n_x)
    ex = np.exp(-1j * math.pi * np.asarray(u_az, dtype=np.float64)[:, None]
                * geometry.x_half_wl[None, :])  # (K, n_x)
    per_row = np.einsum("kzx,kx->kz", w, ex, optimize=False)
    ez = np.exp(-1j * math.pi * np.outer(geometry.z_half_wl, u_el))
    return np.einsum("kz,zq->kq", per_row, ez, optimize=False)
