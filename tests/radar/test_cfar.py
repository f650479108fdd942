"""Detection primitives (sim2radar.radar.cfar): CFAR thresholds against their closed forms and
Monte Carlo, TI's CASO passes and angle peak search against literal ports of TI's MATLAB,
false-alarm rates on noise, the peak fit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.radar import cfar
from tests.radar import _ti_reference as ti


@pytest.mark.parametrize("n", [8, 16, 248])
@pytest.mark.parametrize("pfa", [1e-3, 1e-6])
def test_ca_threshold_is_richards_closed_form(n, pfa):
    """Single look: alpha = N (P_fa^(-1/N) - 1) (Richards §6.5)."""
    assert cfar.cfar_threshold_factor("ca", n, pfa) == pytest.approx(n * (pfa ** (-1 / n) - 1),
                                                                     rel=1e-6)


@pytest.mark.parametrize("n, rank", [(16, 0.75), (24, 0.5), (248, 0.75)])
def test_os_threshold_is_rohlings(n, rank):
    """Single look: P_fa = prod_{i<k} (N - i) / (N - i + alpha) (Rohling 1983) at the design
    value."""
    pfa = 1e-4
    alpha = cfar.cfar_threshold_factor("os", n, pfa, rank=rank)
    k = math.ceil(rank * n)
    got = np.prod([(n - i) / (n - i + alpha) for i in range(k)])
    assert got == pytest.approx(pfa, rel=1e-5)


def test_caso_single_look_is_the_closed_form():
    """One look, n cells a side: P_fa = 2 sum_{k<n} C(n-1+k, k) (2 + alpha/n)^-(n+k), the
    smallest-of CA-CFAR in Gaussian noise (Weiss, IEEE TAES 18(1), 1982, eq. (13))."""
    for n, alpha in ((4, 3.0), (8, 5.0), (16, 2.0)):
        want = 2 * sum(math.comb(n - 1 + k, k) * (2 + alpha / n) ** -(n + k) for k in range(n))
        assert cfar.caso_false_alarm_rate(alpha, n, 1) == pytest.approx(want, rel=1e-6)


@pytest.mark.parametrize("kind", ["ca", "caso", "os"])
def test_multi_look_threshold_by_monte_carlo(kind):
    """K = 4 non-coherent looks, 8 cells a side: the false-alarm rate of Gamma(4) cells at the
    designed alpha is the design value (2e5 draws, within 10 %)."""
    n_side, looks, pfa = 8, 4, 1e-2
    n_train = n_side if kind == "caso" else 2 * n_side
    alpha = cfar.cfar_threshold_factor(kind, n_train, pfa, looks=looks, rank=0.75)
    rng = np.random.default_rng(0)
    left = rng.gamma(looks, size=(200_000, n_side))
    right = rng.gamma(looks, size=(200_000, n_side))
    cut = rng.gamma(looks, size=200_000)
    both = np.concatenate([left, right], axis=1)
    z = {"ca": both.mean(axis=1),
         "caso": np.minimum(left.mean(axis=1), right.mean(axis=1)),
         "os": np.sort(both, axis=1)[:, 11]}[kind]
    assert np.mean(cut > alpha * z) == pytest.approx(pfa, rel=0.1)


def test_ti_range_pass_equals_the_matlab_port():
    """cfar_1d(edges='ti') is CFAR_CASO_Range.m cell for cell: random maps with strong targets,
    the first 10 / last 20 bins discarded, TI's copy padding at both ends."""
    rng = np.random.default_rng(3)
    sig = rng.gamma(4.0, size=(96, 16))
    sig[[12, 40, 41, 80], [0, 5, 5, 15]] *= [40.0, 12.0, 30.0, 50.0]
    det, _ = cfar.cfar_1d(sig, axis=0, kind="caso", guard=8, train=8, alpha=5.0, edges="ti",
                          discard=(10, 20))
    want = set(ti.caso_range(sig, 8, 8, 5.0, (10, 20)))
    assert set(zip(*np.nonzero(det), strict=True)) == want
    assert want  # the targets are found


def test_doppler_pass_equals_the_matlab_port():
    rng = np.random.default_rng(4)
    sig = rng.gamma(2.0, size=(20, 64))
    sig[3, [0, 31, 63]] *= 20.0
    det, _ = cfar.cfar_1d(sig, axis=1, kind="caso", guard=0, train=4, alpha=3.0, edges="wrap")
    assert set(zip(*np.nonzero(det), strict=True)) == ti.caso_doppler(sig, 4, 0, 3.0)


@pytest.mark.parametrize("kind, looks", [("caso", 1), ("caso", 192), ("ca", 16)])
def test_1d_false_alarm_rate_on_noise_is_the_design_value(kind, looks):
    """Square-law noise cells of K looks through cfar_1d at the designed alpha: false alarms
    within 10 % of the design P_fa = 1e-3 (~1,000 expected)."""
    pfa = 1e-3
    rng = np.random.default_rng(5)
    power = rng.gamma(looks, size=(1_000_000 // 64, 64))
    n_train = 8 if kind == "caso" else 16
    alpha = cfar.cfar_threshold_factor(kind, n_train, pfa, looks=looks)
    det, _ = cfar.cfar_1d(power, axis=1, kind=kind, guard=2, train=8, alpha=alpha, edges="wrap")
    assert det.mean() == pytest.approx(pfa, rel=0.1)


def test_ti_default_thresholds_have_vanishing_design_false_alarm_rates():
    """TI's K0 = 5 (range, 8 cells a side) and 3 (Doppler, 4 a side) on a map summed over 192
    channels: the design false-alarm rates are below 1e-50 — noise alone never crosses them;
    what TI's chain detects is signal and its leakage."""
    assert cfar.caso_false_alarm_rate(5.0, 8, 192) < 1e-50
    assert cfar.caso_false_alarm_rate(3.0, 4, 192) < 1e-50


def test_cfar_detect_false_alarms_on_white_exponential_cells():
    """2-D CA and OS on independent exponential cells: the design value within 15 %."""
    pfa = 1e-2
    rng = np.random.default_rng(1)
    power = rng.exponential(size=(2, 384, 384))
    guard, train = (1, 1), (4, 3)
    n = len(cfar.training_offsets(guard, train))
    for kind in ("ca", "os"):
        alpha = cfar.cfar_threshold_factor(kind, n, pfa, rank=0.75)
        mask = cfar.cfar_detect(power, kind=kind, guard=guard, train=train, alpha=alpha)
        assert mask.mean() == pytest.approx(pfa, rel=0.15), kind


def test_training_window_and_white_cells_are_independent():
    off = cfar.training_offsets((2, 2), (8, 4))
    assert len(off) == 21 * 13 - 5 * 5
    white = np.zeros(64)
    white[0] = 1.0
    assert cfar.effective_training_cells(off, white, white) == pytest.approx(len(off))
    assert cfar.effective_training_cells_os(off, white, white, 0.75) == pytest.approx(len(off))
    assert cfar.effective_side_cells(8, white) == pytest.approx(8)
    # a Hann-windowed axis correlates neighbours: fewer independent cells
    w2 = np.hanning(66)[1:-1] ** 2
    hann = cfar.power_correlation(w2, 64)
    assert cfar.effective_training_cells(off, hann, white) < 0.8 * len(off)
    assert cfar.effective_side_cells(8, hann) < 6


def test_hysteresis_peaks_equal_the_matlab_port():
    """hysteresis_peaks is DOA_BF_PeakDet_loc.m (with its documented deviation) on 300 angle
    spectra: noise-like ones and single-source ones, 1 dB and 0 dB sidelobe levels."""
    rng = np.random.default_rng(0)
    gamma = 10 ** (0.2 / 10)
    for t in range(300):
        if t % 3:
            x = rng.standard_normal(86) + 1j * rng.standard_normal(86)
        else:
            x = np.exp(1j * np.pi * rng.uniform(-1, 1) * np.arange(86)) + 0.05 * rng.standard_normal(86)
        mag = np.abs(np.fft.fft(x, 256))
        for sl in (1.0, 0.0):
            got = np.flatnonzero(cfar.hysteresis_peaks(mag[None], gamma=gamma,
                                                       sidelobe_db=sl)[0]).tolist()
            assert got == ti.peak_det_loc(mag, gamma, sl)


def test_hysteresis_peaks_of_many_rows_are_each_rows_own():
    """The scan runs on all rows at once, and past the end only on the rows that armed, each
    to its own end: every row's peaks are those it gets alone (rows that arm late or never,
    ties, spectra whose peak wraps around)."""
    rng = np.random.default_rng(1)
    n = 64
    rows = [np.abs(np.fft.fft(rng.standard_normal(20) + 1j * rng.standard_normal(20), n))
            for _ in range(40)]
    rows += [np.linspace(0.0, 1.0, n),                           # rising: arms only at the end
             np.linspace(1.0, 0.0, n),                           # falling: never arms
             np.round(rng.random(n) * 3),                        # ties
             np.roll(np.exp(-0.5 * ((np.arange(n) - 32) / 3.0) ** 2), 32)]  # peak at the wrap
    spectra = np.array(rows)
    gamma = 10 ** (0.2 / 10)
    for sl in (1.0, 0.0):
        together = cfar.hysteresis_peaks(spectra, gamma=gamma, sidelobe_db=sl)
        alone = np.array([cfar.hysteresis_peaks(r[None], gamma=gamma, sidelobe_db=sl)[0]
                          for r in spectra])
        assert np.array_equal(together, alone)
    assert together.any(axis=1).sum() > 40


def test_one_source_gives_one_azimuth_peak():
    """An unwindowed 86-element aperture: its -13 dB sidelobes are far below TI's 1 dB rule,
    so one source is one peak at its bin."""
    k = 37
    x = np.exp(2j * np.pi * k * np.arange(86) / 256)
    mag = np.abs(np.fft.fft(x, 256))
    peaks = cfar.hysteresis_peaks(mag[None], gamma=10 ** 0.02, sidelobe_db=1.0)[0]
    assert np.flatnonzero(peaks).tolist() == [k]


def test_parabolic_peak_recovers_a_gaussian_vertex():
    x0 = 0.3
    y = -((np.array([-1.0, 0.0, 1.0]) - x0) ** 2) / 2.0
    off, inc = cfar.parabolic_peak(*y, max_offset=0.5)
    assert off == pytest.approx(x0) and inc == pytest.approx(-y[1] + 0.0 - (-0.0), abs=0.05)
    off, _ = cfar.parabolic_peak(np.array(0.0), np.array(0.0), np.array(5.0), max_offset=1.0)
    assert off == 0.0  # not curving downwards: no shift
