"""Literal NumPy ports of TI's cascade MATLAB detection functions (4chip_cascade_MIMO_example,
``modules/detection/@CFAR_CASO/CFAR_CASO_Range.m``, ``CFAR_CASO_Doppler_overlap.m`` and
``modules/DOA/DOA_BF_PeakDet_loc.m``), written loop by loop as the MATLAB reads (1-based indices
turned 0-based), as the reference twins of :mod:`sim2radar.radar.cfar`'s vectorised versions.
"""

from __future__ import annotations

import numpy as np


def caso_range(sig: np.ndarray, ref: int, guard: int, k0: float, discard: tuple[int, int]
               ) -> list[tuple[int, int]]:
    """``CFAR_CASO_Range.m``: (range, Doppler) detections of a (M, D) linear-power map."""
    m_samp, n_dop = sig.shape
    gaptot = guard + ref
    out = []
    for k in range(n_dop):
        vec = sig[discard[0]:m_samp - discard[1], k]
        vec = np.concatenate([vec[:gaptot], vec, vec[-gaptot:]])
        for j in range(m_samp - discard[0] - discard[1]):
            a = vec[j:j + ref]                                    # cells j-gaptot .. j-guard-1
            b = vec[j + gaptot + guard + 1:j + 2 * gaptot + 1]    # cells j+guard+1 .. j+gaptot
            noise = min(a.sum() / ref, b.sum() / ref)
            if vec[j + gaptot] > k0 * noise:
                out.append((j + discard[0], k))
    return out


def caso_doppler(sig: np.ndarray, ref: int, guard: int, k0: float) -> set[tuple[int, int]]:
    """``CFAR_CASO_Doppler_overlap.m`` without the range-hit intersection: (range, Doppler)
    cells passing the circular Doppler CASO test, for every range row."""
    m_samp, n_dop = sig.shape
    gaptot = guard + ref
    out = set()
    for r in range(m_samp):
        sigv = sig[r]
        vec = np.concatenate([sigv[-gaptot:], sigv, sigv[:gaptot]])
        for j in range(n_dop):
            jj = j + gaptot
            a = vec[jj - gaptot:jj - guard]
            b = vec[jj + guard + 1:jj + gaptot + 1]
            if vec[jj] > k0 * min(a.sum() / ref, b.sum() / ref):
                out.add((r, j))
    return out


def peak_det_loc(in_data: np.ndarray, gamma: float, sidelobe_db: float) -> list[int]:
    """``DOA_BF_PeakDet_loc.m`` on a magnitude spectrum: the kept peak locations (0-based),
    with the one documented deviation of :func:`sim2radar.radar.cfar.hysteresis_peaks` (the
    location moves with the value when the scan re-arms)."""
    n = len(in_data)
    min_val, max_val, max_loc = np.inf, 0.0, 0
    locate, extend, init, abs_max = False, 0, True, 0.0
    found = []
    i = 0
    while i < n + extend - 1:
        i += 1
        loc = (i - 1) % n
        cur = in_data[loc]
        abs_max = max(abs_max, cur)
        if cur > max_val:
            max_val, max_loc = cur, loc
        min_val = min(min_val, cur)
        if locate:
            if cur < max_val / gamma:
                found.append((max_loc, max_val))
                min_val = cur
                locate = False
        elif cur > min_val * gamma:
            locate, max_val, max_loc = True, cur, loc
            if init:
                extend, init = i, False
    return sorted({loc for loc, v in found if v >= abs_max * 10 ** (-sidelobe_db / 10)})
