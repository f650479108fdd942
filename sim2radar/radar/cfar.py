"""Detection primitives shared by both radars: CFAR detectors and their thresholds, the angle
peak search of TI's cascade chain, and sub-bin peak interpolation.

The ray tracer's detection (:mod:`sim2radar.radar.detection`) and the reference radar's TI chain
(:mod:`sim2radar.radar.processing`) both detect with the functions here; nothing else in the
package implements a CFAR or a peak fit.

CFAR detectors
--------------
A cell under test (CUT) of square-law power ``P`` is a detection when ``P > alpha * Z``, ``Z``
an estimate of the interference from ``train`` reference cells on each side of the CUT beyond
``guard`` guard cells (Richards, *Fundamentals of Radar Signal Processing*, 2nd ed., §6.5):

* ``ca`` (cell averaging): ``Z`` = mean of all reference cells;
* ``caso`` (cell averaging, smallest of): ``Z = min(mean(left), mean(right))`` — TI's
  ``CFAR_CASO_Range.m`` / ``CFAR_CASO_Doppler_overlap.m`` of the 4-chip cascade MIMO example
  (Richards §6.5.5, "SOCA"); it keeps a target next to a strong one on one side;
* ``os`` (ordered statistic): ``Z`` = the ``k``-th smallest reference cell, ``k = ceil(rank
  N)`` (Rohling, IEEE TAES 19(4), 608-621, 1983).

Thresholds from a design false-alarm rate (:func:`cfar_threshold_factor`), each cell the sum
of ``K`` independent square-law looks (``K`` = virtual channels for TI's non-coherently
integrated map) with unit-mean exponential looks, so a cell is ``Gamma(K)``:

* CA: ``X / (X + S) ~ Beta(K, N K)`` for ``S`` the training sum, so ``P_fa = I_{1-b}(N K,
  K)`` with ``b = alpha / (N + alpha)`` (Richards §6.5 generalised to ``K`` looks); single
  look: ``alpha = N (P_fa^(-1/N) - 1)``.
* CASO: each side's mean ``A ~ Gamma(n K, 1/n)``, ``min(A, B)`` has density ``2 f_A (1 -
  F_A)``, so ``P_fa = int_0^1 2 (1 - u) Q(K, alpha F_A^{-1}(u)) du`` with ``Q`` the
  regularised upper incomplete gamma function (Richards §6.5.5 for ``K = 1``), by quadrature.
* OS: Rohling 1983, eq. (19), for one look; numerically integrated over the order
  statistic's Beta density for ``K > 1``.

Neighbouring cells of a windowed, zero-padded FFT are correlated, which makes fewer
*independent* reference cells than there are; the power correlation of two cells is
``|rho|^2`` (Gaussian noise) with ``rho`` the normalised DFT of the noise's window-squared
profile (:func:`power_correlation`), and the reference sum's variance matches a Gamma sum of
``N_eff = N^2 / sum_ij |rho_ij|^2`` independent cells (Satterthwaite, Biometrics Bull. 2(6),
1946), which replaces ``N`` (per side for CASO) in the formulas above.

Angle peaks
-----------
:func:`hysteresis_peaks` is TI's ``DOA_BF_PeakDet_loc.m`` (cascade example, ``modules/DOA``):
a circular scan of an angle *magnitude* spectrum that declares a peak when the spectrum falls
``gamma`` below the running maximum after having risen ``gamma`` above the running minimum
(hysteresis), and keeps the peaks ``>= max * 10^(-sidelobe_db / 10)`` (TI applies the dB
figure with ``/10`` to magnitudes; so does this function).

Peak interpolation
------------------
:func:`parabolic_peak`: the vertex of the parabola through three log powers (Gaussian
interpolation; Gasior & Gonzalez, CERN-AB-2004-023, eq. (7)), exact for a Gaussian main lobe.
"""

from __future__ import annotations

import functools
import math

import numpy as np

# scipy's integrate/ndimage/optimize/special/stats are imported where used (~0.5 s together):
# importing sim2radar.radar (a radar config, a cached rerun) does not pay for them (issue #23).

__all__ = [
    "CFAR_KINDS",
    "EDGE_MODES",
    "cfar_window",
    "ca_cfar_mask",
    "caso_false_alarm_rate",
    "cfar_1d",
    "cfar_detect",
    "cfar_threshold_factor",
    "effective_side_cells",
    "effective_training_cells",
    "effective_training_cells_os",
    "hysteresis_peaks",
    "is_local_max",
    "parabolic_peak",
    "power_correlation",
    "training_offsets",
]

#: CFAR kinds :func:`cfar_1d` and :func:`cfar_threshold_factor` know.
CFAR_KINDS = ("ca", "caso", "os")
#: How :func:`cfar_1d` treats the reference windows at the ends of the axis: ``wrap``
#: (circular, a DFT axis), ``ti`` (TI's range pass: only cells ``discard[0] ..
#: L - 1 - discard[1]`` are tested, on that truncated vector padded with copies of its own
#: first and last ``guard + train`` cells).
EDGE_MODES = ("wrap", "ti")


# -- reference windows and their independent-cell counts ----------------------------------
def training_offsets(guard: tuple[int, int], train: tuple[int, int]) -> np.ndarray:
    """(N, 2) int — offsets of a 2-D CFAR's training cells: the ``(g + t)`` rectangle minus
    the ``g`` rectangle (each side, per axis)."""
    (g0, g1), (t0, t1) = guard, train
    a = np.arange(-(g0 + t0), g0 + t0 + 1)
    b = np.arange(-(g1 + t1), g1 + t1 + 1)
    aa, bb = np.meshgrid(a, b, indexing="ij")
    keep = ~((np.abs(aa) <= g0) & (np.abs(bb) <= g1))
    return np.column_stack([aa[keep], bb[keep]])


def power_correlation(profile: np.ndarray, n_fft: int) -> np.ndarray:
    """(n_fft,) — ``|rho(lag)|^2`` between DFT bins of noise whose variance along the
    transformed axis is ``profile`` (e.g. the window squared)."""
    rho = np.fft.fft(profile, n_fft) / profile.sum()
    return np.abs(rho) ** 2


def effective_training_cells(offsets: np.ndarray, corr0: np.ndarray, corr1: np.ndarray) -> float:
    """``N_eff = N^2 / sum_ij |rho_0(di)|^2 |rho_1(dj)|^2`` of 2-D training ``offsets``."""
    d0 = offsets[:, None, 0] - offsets[None, :, 0]
    d1 = offsets[:, None, 1] - offsets[None, :, 1]
    var = (corr0[d0 % len(corr0)] * corr1[d1 % len(corr1)]).sum()
    return float(len(offsets) ** 2 / var)


def effective_side_cells(n_cells: int, corr: np.ndarray) -> float:
    """``N_eff`` of ``n_cells`` contiguous cells along an axis of power correlation ``corr``."""
    lag = np.arange(n_cells)[:, None] - np.arange(n_cells)[None, :]
    return float(n_cells**2 / corr[lag % len(corr)].sum())


def effective_training_cells_os(offsets: np.ndarray, corr0: np.ndarray, corr1: np.ndarray,
                                rank: float) -> float:
    """Independent-cell equivalent of correlated training cells for an OS-CFAR of ``rank``.

    The sample ``p``-quantile's variance is ``sum_ij Cov(1{X_i <= q}, 1{X_j <= q}) / (N f(q))^2``
    (Bahadur, Ann. Math. Statist. 37(3), 1966), so ``N_os = N^2 p (1 - p) / sum_ij Cov_ij``.
    Two square-law cells with power correlation ``rho`` follow Kibble's bivariate exponential
    (Kibble, Sankhya 5(2), 1941), whose Laguerre series gives ``Cov = sum_{k>=1} rho^k I_k^2``,
    ``I_k = q e^{-q} L^{(1)}_{k-1}(q) / k``, ``q = -ln(1 - p)`` (single look)."""
    from scipy import special

    p = float(rank)
    q = -math.log(max(1.0 - p, 1e-12))
    k = np.arange(1, 161)
    i_k = q * math.exp(-q) * special.eval_genlaguerre(k - 1, 1, q) / k
    d0 = offsets[:, None, 0] - offsets[None, :, 0]
    d1 = offsets[:, None, 1] - offsets[None, :, 1]
    rho = corr0[d0 % len(corr0)] * corr1[d1 % len(corr1)]
    uniq, inv = np.unique(np.round(rho, 12), return_inverse=True)
    cov_u = (np.clip(uniq, 0.0, 1.0)[:, None] ** k[None, :] * i_k[None, :] ** 2).sum(axis=1)
    cov = cov_u[inv.reshape(rho.shape)]
    np.fill_diagonal(cov, p * (1.0 - p))
    return float(len(offsets) ** 2 * p * (1.0 - p) / cov.sum())


# -- thresholds ---------------------------------------------------------------------------
@functools.lru_cache(maxsize=1024)
def caso_false_alarm_rate(alpha: float, n_side: float, looks: int = 1) -> float:
    """False-alarm probability of a CASO-CFAR (module doc): ``P(X > alpha min(A, B))`` for a
    ``Gamma(K)`` cell and two independent side means of ``n_side`` ``Gamma(K)`` cells.

    Parameters
    ----------
    alpha : float — linear threshold factor (TI's ``K0``).
    n_side : float — (effective) independent reference cells per side.
    looks : int — non-coherently summed looks per cell ``K``.

    Rates above ~1e-14 are exact to quadrature precision; the integral runs over the side
    means' central ``1 - 2e-15`` probability, so a smaller rate is reported as a value below
    ~1e-14 (TI's ``K0 = 5`` on 192 looks: effectively zero).

    Cached (a pure function of its arguments): the reference radar reports the design rate of
    its fixed ``K0`` every frame, and the quadrature takes ~30 ms.
    """
    from scipy import integrate, special, stats

    k, shape = float(looks), float(n_side) * float(looks)

    def f(m: float) -> float:  # density of min(A, B) times the CUT's survival function
        return (2.0 * stats.gamma.pdf(m, shape, scale=1.0 / float(n_side))
                * stats.gamma.sf(m, shape, scale=1.0 / float(n_side))
                * special.gammaincc(k, alpha * m))

    # the side means concentrate around K (relative width 1 / sqrt(n K)): integrate there
    lo = stats.gamma.ppf(1e-15, shape, scale=1.0 / float(n_side))
    hi = stats.gamma.isf(1e-15, shape, scale=1.0 / float(n_side))
    val, _ = integrate.quad(f, lo, hi, limit=400, epsabs=0.0, epsrel=1e-9,
                            points=[k] if lo < k < hi else None)
    return float(val)


@functools.lru_cache(maxsize=256)
def cfar_threshold_factor(kind: str, n_train: float, pfa: float, *, looks: int = 1,
                          rank: float = 0.75) -> float:
    """CFAR scale ``alpha`` for a design false-alarm rate (module doc).

    Parameters
    ----------
    kind : ``"ca"``, ``"caso"`` or ``"os"``.
    n_train : float — (effective) number of independent training cells; for ``caso`` the
        number *per side*.
    pfa : float — design false-alarm probability per cell.
    looks : int — non-coherently summed looks per cell (1: square-law single look).
    rank : float — OS: the order statistic as a fraction of the training cells.

    Returns
    -------
    alpha : float — detect when ``P > alpha * Z`` (module doc).
    """
    from scipy import integrate, optimize, special, stats

    n, k_looks = float(n_train), int(looks)
    if kind == "ca":
        # P(X > alpha/N S) with X ~ Gamma(K), S ~ Gamma(N K): X / (X + S) ~ Beta(K, N K)
        b = stats.beta.isf(pfa, k_looks, n * k_looks)
        return float(n * b / (1.0 - b))
    if kind == "caso":
        target = math.log(pfa)
        lo, hi = 1.0, 2.0
        while math.log(max(caso_false_alarm_rate(hi, n, k_looks), 1e-300)) > target:
            lo, hi = hi, 2.0 * hi
            if hi > 1e9:
                raise ValueError(f"CASO-CFAR: no threshold reaches pfa={pfa} with {n} cells "
                                 "per side")
        return float(optimize.brentq(
            lambda a: math.log(max(caso_false_alarm_rate(a, n, k_looks), 1e-300)) - target,
            0.0 if lo == 1.0 else lo, hi, xtol=1e-10))
    if kind != "os":
        raise ValueError(f"unknown CFAR kind {kind!r}; known: {', '.join(CFAR_KINDS)}")
    k = max(1.0, min(n, math.ceil(rank * n - 1e-9) if float(n).is_integer() else rank * n))

    if k_looks == 1:  # Rohling 1983, eq. (19), in log-gamma form (real N, k allowed)
        def log_pfa(t: float) -> float:
            return (special.gammaln(n + 1) - special.gammaln(n - k + 1)
                    + special.gammaln(t + n - k + 1) - special.gammaln(t + n + 1))
    else:
        def log_pfa(t: float) -> float:
            def f(b: float) -> float:
                z = stats.gamma.ppf(b, k_looks)
                return stats.gamma.sf(t * z, k_looks) * stats.beta.pdf(b, k, n - k + 1)

            val, _ = integrate.quad(f, 0.0, 1.0, limit=200, epsabs=0.0, epsrel=1e-8)
            return math.log(max(val, 1e-300))

    target = math.log(pfa)
    hi = 1.0
    while log_pfa(hi) > target:
        hi *= 2.0
        if hi > 1e9:
            raise ValueError(f"OS-CFAR: no threshold reaches pfa={pfa} with N={n}, k={k}")
    return float(optimize.brentq(lambda t: log_pfa(t) - target, 0.0, hi, xtol=1e-10))


# -- detectors ----------------------------------------------------------------------------
def cfar_window(n_len: int, *, kind: str, guard: int, train: int, edges: str,
                discard: tuple[int, int] = (0, 0)) -> tuple[int, int, int, int, int]:
    """The window of one CFAR pass over an axis of ``n_len`` cells, checked: ``(guard,
    train, span = guard + train, lo, hi)`` with ``lo``/``hi`` the cells never tested at the
    start / end (``ti`` edges). Shared by :func:`cfar_1d` and its torch twin
    (:func:`sim2radar.radar.detection_torch.cfar_1d`).

    Raises
    ------
    ValueError — an unknown kind or edge mode, fewer than 1 reference or a negative guard
        cell, or a window that does not fit the cells tested.
    """
    if kind not in CFAR_KINDS:
        raise ValueError(f"unknown CFAR kind {kind!r}; known: {', '.join(CFAR_KINDS)}")
    if edges not in EDGE_MODES:
        raise ValueError(f"unknown CFAR edge mode {edges!r}; known: {', '.join(EDGE_MODES)}")
    if int(train) < 1 or int(guard) < 0:
        raise ValueError(f"CFAR needs train >= 1 and guard >= 0 cells, got {train}, {guard}")
    g, n = int(guard), int(train)
    span = g + n
    lo, hi = (int(discard[0]), int(discard[1])) if edges == "ti" else (0, 0)
    length = max(n_len - lo - hi, 0)
    if length < 1 or (edges == "wrap" and 2 * span + 1 > n_len) or (edges == "ti"
                                                                    and span > length):
        raise ValueError(f"CFAR window of {2 * span + 1} cells (guard {g}, reference {n} per "
                         f"side) does not fit the {length} cells tested; reduce the CFAR's "
                         "guard or reference cells")
    return g, n, span, lo, hi


def cfar_1d(power: np.ndarray, *, axis: int = -1, kind: str = "caso", guard: int,
            train: int, alpha: float, edges: str = "wrap", discard: tuple[int, int] = (0, 0),
            rank: float = 0.75, candidates: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """One CFAR pass along one axis of a power array (every other axis independent).

    Parameters
    ----------
    power : (..., L, ...) float — square-law cells (linear power).
    axis : int — the axis the reference windows run along.
    kind : ``"ca"``, ``"caso"`` or ``"os"`` (module doc).
    guard, train : int — guard and reference cells on *each* side.
    alpha : float — linear threshold factor (TI's ``K0``).
    edges : ``"wrap"`` (circular) or ``"ti"`` (:data:`EDGE_MODES`).
    discard : (int, int) — ``ti`` edges: cells at the start / end of the axis never tested
        (TI's ``discardCellLeft`` / ``discardCellRight``).
    rank : float — ``os`` only.
    candidates : bool array like ``power``, optional — only these cells may be detections.

    Returns
    -------
    detected : bool array like ``power``
    interference : float array like ``power`` — the estimate ``Z`` per cell (NaN where not
        tested).
    """
    p = np.moveaxis(np.asarray(power, dtype=np.float64), axis, -1)
    n_len = p.shape[-1]
    g, n, span, lo, hi = cfar_window(n_len, kind=kind, guard=guard, train=train, edges=edges,
                                     discard=discard)
    v = p[..., lo:n_len - hi]
    length = v.shape[-1]
    if edges == "wrap":
        padded = np.concatenate([v[..., length - span:], v, v[..., :span]], axis=-1)
    else:  # TI: copies (same order) of the truncated vector's own first and last cells
        padded = np.concatenate([v[..., :span], v, v[..., length - span:]], axis=-1)
    win = np.lib.stride_tricks.sliding_window_view(padded, n, axis=-1)  # (..., L + 2s - n + 1, n)
    j = np.arange(length)
    left = win[..., j + span - g - n, :]                                    # cells j-g-n..j-g-1
    right = win[..., j + span + g + 1, :]                                   # cells j+g+1..j+g+n
    if kind == "ca":
        z = 0.5 * (left.mean(axis=-1) + right.mean(axis=-1))
    elif kind == "caso":
        z = np.minimum(left.mean(axis=-1), right.mean(axis=-1))
    else:
        both = np.concatenate([left, right], axis=-1)
        k = max(1, min(2 * n, math.ceil(rank * 2 * n - 1e-9)))
        z = np.partition(both, k - 1, axis=-1)[..., k - 1]
    det_v = v > alpha * z
    detected = np.zeros(p.shape, dtype=bool)
    interference = np.full(p.shape, np.nan)
    detected[..., lo:n_len - hi] = det_v
    interference[..., lo:n_len - hi] = z
    detected = np.moveaxis(detected, -1, axis)
    interference = np.moveaxis(interference, -1, axis)
    if candidates is not None:
        detected &= np.asarray(candidates, dtype=bool)
    return detected, interference


def cfar_detect(power: np.ndarray, *, kind: str, guard: tuple[int, int],
                train: tuple[int, int], alpha: float, rank: float = 0.75,
                candidates: np.ndarray | None = None) -> np.ndarray:
    """Boolean detection mask of a 2-D CA or OS CFAR over a power plane (or a stack of planes,
    leading axes), the training cells a rectangle minus the guard rectangle
    (:func:`training_offsets`), both axes circular.

    Parameters
    ----------
    power : (..., n0, n1) float — square-law cells.
    kind : ``"ca"`` or ``"os"``; guard, train : (int, int) per axis, each side.
    alpha, rank : see :func:`cfar_threshold_factor`.
    candidates : same shape, bool, optional — only these cells are tested (e.g. local maxima).

    Returns
    -------
    (..., n0, n1) bool
    """
    from scipy import ndimage

    p = np.asarray(power, dtype=np.float64)
    n0, n1 = p.shape[-2:]
    (g0, g1), (t0, t1) = guard, train
    if 2 * (g0 + t0) + 1 > n0 or 2 * (g1 + t1) + 1 > n1:
        raise ValueError(f"CFAR window {2 * (g0 + t0) + 1} x {2 * (g1 + t1) + 1} cells does not "
                         f"fit the {n0} x {n1} plane; reduce cfar_guard_cells / "
                         "cfar_training_cells")
    cand = np.ones(p.shape, bool) if candidates is None else np.asarray(candidates, bool)
    offsets = training_offsets(guard, train)
    n_train = len(offsets)
    out = np.zeros(p.shape, dtype=bool)
    if kind == "ca":
        lead = (1,) * (p.ndim - 2)

        def box(size0: int, size1: int) -> np.ndarray:
            return ndimage.uniform_filter(p, size=lead + (size0, size1), mode="wrap") * (
                size0 * size1)

        s = box(2 * (g0 + t0) + 1, 2 * (g1 + t1) + 1) - box(2 * g0 + 1, 2 * g1 + 1)
        return cand & (p > alpha * s / n_train)
    if kind != "os":
        raise ValueError(f"unknown 2-D CFAR kind {kind!r}; known: 'ca', 'os'")
    k = max(1, min(n_train, math.ceil(rank * n_train - 1e-9)))
    idx = np.nonzero(cand)
    flat_p = p.reshape(-1, n0, n1)
    lead_idx = (np.ravel_multi_index(idx[:-2], p.shape[:-2]) if p.ndim > 2
                else np.zeros(len(idx[0]), np.int64))
    i0, i1 = idx[-2], idx[-1]
    det = np.zeros(len(i0), bool)
    step = max(1, (1 << 22) // n_train)
    for s in range(0, len(i0), step):
        sl = slice(s, s + step)
        r0 = (i0[sl, None] + offsets[None, :, 0]) % n0
        r1 = (i1[sl, None] + offsets[None, :, 1]) % n1
        vals = flat_p[lead_idx[sl, None], r0, r1].astype(np.float32)
        kth = np.partition(vals, k - 1, axis=1)[:, k - 1]
        det[sl] = flat_p[lead_idx[sl], i0[sl], i1[sl]] > alpha * kth
    out[tuple(ix[det] for ix in idx)] = True
    return out


def is_local_max(p: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """True where a candidate cell is >= all its ``3^ndim - 1`` neighbours (zero outside).

    Only the (few) candidate cells are tested, which is much cheaper than a full maximum
    filter over a cube.
    """
    idx = np.nonzero(candidates)
    out = np.zeros_like(candidates)
    if len(idx[0]) == 0:
        return out
    padded = np.pad(p, 1, mode="constant", constant_values=0.0)
    centre = p[idx]
    keep = np.ones(len(centre), dtype=bool)
    for offset in np.ndindex(*(3,) * p.ndim):
        if all(o == 1 for o in offset):
            continue
        neighbour = padded[tuple(i + o for i, o in zip(idx, offset, strict=True))]
        keep &= centre >= neighbour
    out[tuple(i[keep] for i in idx)] = True
    return out


def ca_cfar_mask(power: np.ndarray, *, guard: int, train: int, threshold_db: float,
                 noise_power: float, min_snr_db: float, sidelobe_level_db: float | None,
                 peak_grouping: bool) -> np.ndarray:
    """The ray tracer's detector: CA-CFAR along axis 0 (range) of a (n_range, ...) power map
    with the receiver noise added to the interference, a minimum SNR, TI's per-range-bin
    sidelobe rule and optional local maxima (:mod:`sim2radar.radar.detection` says why).

    A cell is a detection when ``P > alpha (mean(training) + N)`` with ``alpha =
    10^(threshold_db / 10)``, ``P > N 10^(min_snr_db / 10)``, ``P >= max(P of its range bin)
    10^(-sidelobe_level_db / 10)`` and (``peak_grouping``) it is a local maximum. Training
    cells beyond the ends of the axis do not exist: the mean is over those that do.

    Parameters
    ----------
    power : (n_range, ...) float — cell power [sim. |a|^2].
    guard, train : int — cells each side along range.
    threshold_db, min_snr_db : float [dB]; sidelobe_level_db : float [dB] or None (keep all).
    noise_power : float — ``N`` per cell [sim. |a|^2].
    peak_grouping : bool
    """
    from scipy import ndimage

    p = np.asarray(power, dtype=np.float64)
    n_full, n_guard = 2 * (guard + train) + 1, 2 * guard + 1

    def window_sum(a: np.ndarray, size: int, axis: int = 0) -> np.ndarray:
        return size * ndimage.uniform_filter1d(a, size, axis=axis, mode="constant", cval=0.0)

    train_sum = window_sum(p, n_full) - window_sum(p, n_guard)
    ones = np.ones(p.shape[0])
    count = window_sum(ones, n_full) - window_sum(ones, n_guard)  # fewer near the ends
    shape = (-1,) + (1,) * (p.ndim - 1)
    mean_train = train_sum / np.maximum(count, 1.0).reshape(shape)
    alpha = 10.0 ** (threshold_db / 10.0)
    mask = (p > alpha * (mean_train + noise_power)) & (
        p > noise_power * 10.0 ** (min_snr_db / 10.0))
    if sidelobe_level_db is not None and p.ndim > 1:
        strongest = p.reshape(p.shape[0], -1).max(axis=1).reshape(shape)
        mask &= p >= strongest * 10.0 ** (-sidelobe_level_db / 10.0)
    if peak_grouping:
        mask &= is_local_max(p, mask)
    return mask


# -- peaks --------------------------------------------------------------------------------
def parabolic_peak(y_m: np.ndarray, y_0: np.ndarray, y_p: np.ndarray, *,
                   max_offset: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Vertex of the parabola through ``(-1, y_m), (0, y_0), (1, y_p)`` (module doc).

    Parameters
    ----------
    y_m, y_0, y_p : arrays — log powers (or log magnitudes) at the peak and its neighbours.
    max_offset : float — the offset is clipped to ``[-max_offset, max_offset]`` [steps].

    Returns
    -------
    offset : array [steps] — 0 where the samples do not curve downwards.
    increment : array — ``y(vertex) - y_0`` (the log-peak above the sampled peak).
    """
    den = y_m - 2.0 * y_0 + y_p
    ok = den < 0
    delta = np.where(ok, 0.5 * (y_m - y_p) / np.where(ok, den, -1.0), 0.0)
    delta = np.clip(delta, -max_offset, max_offset)
    return delta, 0.25 * (y_p - y_m) * delta


def hysteresis_peaks(spectrum: np.ndarray, *, gamma: float, sidelobe_db: float) -> np.ndarray:
    """TI's angle peak search (``DOA_BF_PeakDet_loc.m``) on each row of ``spectrum``.

    Per row, a circular scan from bin 0 keeps a running maximum and minimum; in the
    "locate maximum" state a peak (the running maximum's location) is declared when the value
    falls below ``max / gamma``, and the scan switches to "locate minimum"; there it re-arms
    when the value rises above ``min * gamma`` (the running maximum restarting from that
    value). The scan continues past the end up to the first arming index, so a peak across
    the wrap is found. Declared peaks ``>= absmax * 10^(-sidelobe_db / 10)`` are kept.

    One deviation from TI's code: when the scan re-arms, TI sets the running maximum's value to
    the current value without moving its location, so a peak that is only that one sample is
    recorded at the previous peak's location; here the location moves with the value.

    Parameters
    ----------
    spectrum : (D, N) float >= 0 — angle *magnitude* spectra (TI's ``abs(FFT)``).
    gamma : float > 1 — hysteresis factor (TI: ``10^(0.2 / 10)``).
    sidelobe_db : float >= 0 — TI's ``sidelobeLevel_dB`` (1 dB azimuth, 0 dB elevation).

    Returns
    -------
    (D, N) bool — the kept peaks.
    """
    s = np.asarray(spectrum, dtype=np.float64)
    if s.ndim != 2:
        raise ValueError(f"spectrum must be (D, N), got shape {s.shape}")
    d, n = s.shape
    cols = np.ascontiguousarray(s.T)             # the scan reads one bin of every row at a time
    abs_max = np.maximum(s.max(axis=1), 0.0) if n else np.zeros(d)  # the scan sees every bin
    max_val = np.zeros(d)
    max_loc = np.zeros(d, dtype=np.int64)
    min_val = np.full(d, np.inf)
    locate = np.zeros(d, dtype=bool)
    extend = np.zeros(d, dtype=np.int64)  # TI's extendLoc (1-based scan index), 0 = not yet
    peaks = np.zeros((d, n), dtype=bool)
    peak_val = np.zeros((d, n))
    # TI: i = i + 1 while i < N + extendLoc - 1 held before. Scan index i = 1..N-1 runs on
    # every row; from i = N on only the armed rows go on (to N + extendLoc - 1), each on its own
    for i in range(1, n):
        loc = i - 1
        cur = cols[loc]
        higher = cur > max_val
        np.copyto(max_val, cur, where=higher)
        np.copyto(max_loc, loc, where=higher)
        np.minimum(min_val, cur, out=min_val)
        declare = locate & (cur < max_val / gamma)
        if declare.any():
            r = np.flatnonzero(declare)
            peaks[r, max_loc[r]] = True
            peak_val[r, max_loc[r]] = max_val[r]
            min_val[r] = cur[r]
        arm = ~locate & (cur > min_val * gamma)
        np.copyto(max_val, cur, where=arm)
        np.copyto(max_loc, loc, where=arm)
        np.copyto(extend, i, where=arm & (extend == 0))
        locate = (locate & ~declare) | arm
    rows = np.flatnonzero(extend > 0)
    mx, ml, mn, lc, ext = max_val[rows], max_loc[rows], min_val[rows], locate[rows], extend[rows]
    for i in range(n, 2 * n):
        active = i < n + ext
        if not active.any():
            break
        loc = (i - 1) % n
        cur = cols[loc, rows]
        higher = active & (cur > mx)
        np.copyto(mx, cur, where=higher)
        np.copyto(ml, loc, where=higher)
        np.copyto(mn, cur, where=active & (cur < mn))
        declare = active & lc & (cur < mx / gamma)
        if declare.any():
            peaks[rows[declare], ml[declare]] = True
            peak_val[rows[declare], ml[declare]] = mx[declare]
            np.copyto(mn, cur, where=declare)
        arm = active & ~lc & (cur > mn * gamma)
        np.copyto(mx, cur, where=arm)
        np.copyto(ml, loc, where=arm)
        lc = (lc & ~declare) | arm
    keep = peaks & (peak_val >= abs_max[:, None] * 10.0 ** (-float(sidelobe_db) / 10.0))
    return keep
