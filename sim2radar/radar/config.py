"""Radar configuration: FMCW chirp, MIMO array, field of view, ray density, detection.

A :class:`RadarConfig` is loaded from YAML (a preset name such as ``"ti-mmwcas"`` or a path)
and validated at the edge; derived values are properties, never typed in:

* range resolution ``dR = c / (2 B)`` (FMCW; TI SWRA553 "Introduction to mmWave sensing:
  FMCW radars", range-resolution section);
* maximum range ``R_max = f_s c / (2 S)`` for complex baseband sampling (same source),
  which equals ``N_adc * dR`` because ``B = S N_adc / f_s``;
* azimuth / elevation resolution of the virtual array: the -3 dB beamwidth of a uniform
  aperture, ``0.886 lambda / D`` with ``D = N d`` (``d = lambda / 2``), i.e. ``1.772 / N`` rad
  for ``N`` filled virtual positions at lambda/2 (86 -> 1.18 deg for the TI cascade).

Antenna positions are given as ``[azimuth, elevation]`` pairs in units of lambda/2
(the TI convention), the virtual array being every TX + RX sum.
"""

from __future__ import annotations

import hashlib
import json
import math
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from sim2radar.configio import DEFAULT_RADAR, read_yaml_mapping, short_repr, short_text
from sim2radar.constants import SPEED_OF_LIGHT_M_S
from sim2radar.em import get_material

__all__ = [
    "DEFAULT_RADAR",
    "DETECTION_DOMAINS",
    "DetectionConfig",
    "HardwareConfig",
    "SignalChainConfig",
    "FIDELITIES",
    "ScatteringConfig",
    "SCATTERING_MODELS",
    "DEFAULT_LOBE_EXPONENTS",
    "DEFAULT_SCATTERING_COEFFICIENTS",
    "RadarConfig",
    "RadarConfigError",
    "load_radar_config",
    "preset_names",
    "PRESET_DIR",
]

#: Folder of the built-in YAML presets.
PRESET_DIR = Path(__file__).parent / "presets"

#: Default effective-roughness scattering coefficients S (fraction of reflected field
#: amplitude scattered diffusely; Degli-Esposti et al., IEEE TAP 55(1), 2007, "ER model").
#: Heuristic values for 77 GHz indoor surfaces: rough masonry scatters more, glass and metal
#: sheets less. Override per material in the YAML ``scattering.coefficients`` mapping.
DEFAULT_SCATTERING_COEFFICIENTS: dict[str, float] = {
    "metal": 0.2,
    "glass": 0.1,
    "wood": 0.35,
    "plasterboard": 0.35,
    "ceramic_tile": 0.3,
    "concrete": 0.5,
    "brick": 0.5,
    "fabric": 0.7,
    "plastic": 0.3,
    "marble": 0.2,
    "carpet_tile": 0.6,
    "vinyl_tile": 0.3,
    "unknown": 0.4,
}

#: Default lobe exponents ``alpha_R`` of the directive scattering model (Degli-Esposti et al.,
#: IEEE TAP 55(1), 2007, "directive model": scattered intensity ~ ((1 + cos psi_R) / 2)^alpha_R
#: around the specular direction; 0 = isotropic over the half-space, larger = narrower lobe).
#: HEURISTIC values, not fitted at 77 GHz: Degli-Esposti et al. fitted alpha_R for building
#: walls at 1.3 GHz and Pascual-Garcia et al. (IEEE Access 4, 2016) for indoor materials at
#: 60 GHz; these numbers only encode the ordering "smoother surface (glass, metal sheet,
#: marble) -> narrower lobe, rough masonry and fabric -> broad lobe". Refit them from
#: measurements (or the papers above) before using the reference radar for quantitative work.
DEFAULT_LOBE_EXPONENTS: dict[str, float] = {
    "metal": 10.0,
    "glass": 20.0,
    "wood": 6.0,
    "plasterboard": 6.0,
    "ceramic_tile": 8.0,
    "concrete": 3.0,
    "brick": 3.0,
    "fabric": 1.0,
    "plastic": 6.0,
    "marble": 10.0,
    "carpet_tile": 1.0,
    "vinyl_tile": 6.0,
    "unknown": 4.0,
}

#: Diffuse scattering models a ScatteringConfig can select (``model``).
SCATTERING_MODELS = ("lambertian", "directive")


class RadarConfigError(ValueError):
    """An invalid radar configuration; the message names the source, the field and the fix."""


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


#: Where the ray tracer's detector runs (``DetectionConfig.domain``).
DETECTION_DOMAINS = ("integrated", "range-azimuth")


class DetectionConfig(_Frozen):
    """Peak detection of the ray tracer (:mod:`sim2radar.radar.detection`).

    ``domain: integrated`` (default) is TI's cascade chain (``CFAR_CASO/datapath.m``,
    ``DOACascade.m``): the map the CFAR tests is the range-Doppler map **integrated over the
    virtual channels** (``sum |s(x, z)|^2`` per cell). The ray tracer has no chirps; on a
    moving rig (``velocity_mps``) its returns go to the Doppler bin of their direction,
    ``-v . u`` in bins of :attr:`RadarConfig.range_rate_resolution_mps`
    (:func:`sim2radar.radar.detection.doppler_bins`), each bin's channels summed on their own;
    at rest every return shares the zero bin. A ``cfar_kind`` CFAR (``caso``: TI's
    smallest-of) runs along range (``cfar_training_cells`` / ``cfar_guard_cells`` per side,
    threshold factor ``10^(cfar_threshold_db / 10)``, TI's ``K0``; the first / last
    ``cfar_discard_range_bins`` never tested) and one along Doppler (``doppler_cfar_*``,
    circular); a cell must pass both. Then, in each detected cell, every azimuth peak of its
    channels' map (a local maximum along azimuth) at least ``min_snr_db`` over the map's noise
    and within ``sidelobe_level_db`` of the cell's strongest peak (TI's
    ``sidelobeLevel_dB_azim``, 1 dB in its example); each peak's elevation is read from the 2D
    beam. A diffuse multipath field spread over many directions is thus compared with the
    integrated return of its whole cell, as the device compares it.

    ``domain: range-azimuth`` is the earlier detector: a cell-averaging CFAR along range in
    every azimuth beam, ``P > alpha * (mean(training cells) + N)`` with ``alpha =
    10**(cfar_threshold_db/10)`` (Richards, *Fundamentals of Radar Signal Processing*, §6.5),
    ``P > N * 10**(min_snr_db/10)``, (``peak_grouping``) a local maximum of its neighbourhood
    (3 cells per axis) and within ``sidelobe_level_db`` of the strongest peak of its range
    bin. Each beam's threshold follows the weak diffuse multipath behind walls and near
    ``R_max`` wherever nothing stronger shares the beam, so it detects that multipath's
    speckle at the CFAR's false-alarm rate everywhere (docs/radar_model.md: 63 % of the
    ground-truth sim's points more than 1 m behind the first surface; the reference radar's
    own paths through a per-beam CFAR: 64 %). Kept for comparisons; it ignores the rig's
    motion.

    ``N`` is the map's receiver noise: ``N0`` (per beam cell of the all-channel matched filter)
    times ``N_virtual / n`` for the ``n`` channel positions the map uses. ``N0`` by default
    (``noise_floor_db: null``) comes from the preset's ``hardware`` link budget
    (:func:`sim2radar.radar.link_budget.noise_power_per_cell`: ``k T F f_s`` over the echo
    scale and the coherent processing gain); a number overrides it [dB re the simulator's
    ``|a|^2`` unit]. Receiver noise is added to the simulated channels only when the frame has a
    seed and ``add_noise`` is on: ``seed=None`` stays deterministic and noise-free (the
    thresholds then use the expected noise).
    """

    domain: Literal["integrated", "range-azimuth"] = Field(
        "integrated", description="where the CFAR runs: the channel-integrated range profile "
        "(TI's chain at rest) or every azimuth beam of the range-azimuth map")
    cfar_kind: Literal["ca", "caso", "os"] = Field(
        "caso", description="integrated domain: cell averaging, smallest-of (TI's CASO) or "
        "ordered statistic (rank 0.75); the range-azimuth domain is always 'ca'")
    cfar_guard_cells: int = Field(8, ge=0, le=64, description="guard cells each side [bins]")
    cfar_training_cells: int = Field(8, ge=1, le=256, description="training cells each side [bins]")
    cfar_threshold_db: float = Field(6.99, ge=0.0, le=60.0,
                                     description="CFAR scale alpha [dB] (TI's K0 = 5: 6.99 dB)")
    cfar_discard_range_bins: tuple[int, int] = Field(
        (10, 20), description="integrated domain: first and last range bins never tested "
        "(TI's discardCellLeft / discardCellRight)")
    doppler_cfar_guard_cells: int = Field(
        0, ge=0, le=16, description="integrated domain, Doppler pass: guard cells each side")
    doppler_cfar_training_cells: int = Field(
        4, ge=1, le=16, description="integrated domain, Doppler pass: training cells each side")
    doppler_cfar_threshold_db: float = Field(
        4.77, ge=0.0, le=60.0, description="integrated domain, Doppler pass: CFAR scale [dB] "
        "(TI's K0 = 3: 4.77 dB)")
    noise_floor_db: float | None = Field(
        None,
        description="receiver noise power per cell [dB re simulator power unit]; "
        "None = derived from the hardware link budget",
    )
    add_noise: bool = Field(
        True, description="add receiver noise to frames simulated with a seed (seed=None: never)"
    )
    min_snr_db: float = Field(10.0, ge=0.0, description="minimum cell SNR over the noise [dB]")
    peak_grouping: bool = Field(
        True, description="range-azimuth domain: keep only local maxima (3 cells per axis)")
    sidelobe_level_db: float | None = Field(
        1.0,
        ge=0.0,
        le=100.0,
        description="drop azimuth peaks more than this below the strongest of their detection "
        "cell (range-Doppler cell; range bin in the range-azimuth domain) [dB]; None keeps all",
    )
    max_points: int | None = Field(None, ge=1, description="keep the strongest N points")

    @field_validator("noise_floor_db")
    @classmethod
    def _check_noise_floor(cls, value: float | None) -> float | None:
        if value is not None and not (math.isfinite(value) and -300.0 < value < 100.0):
            raise ValueError(f"noise_floor_db must be a finite dB value or null, got {value}")
        return value

    @field_validator("cfar_discard_range_bins")
    @classmethod
    def _check_discard(cls, value: tuple[int, int]) -> tuple[int, int]:
        if any(int(v) < 0 for v in value):
            raise ValueError(f"cfar_discard_range_bins must be >= 0 bins, got {list(value)}")
        return (int(value[0]), int(value[1]))

    @model_validator(mode="after")
    def _check_domain(self) -> DetectionConfig:
        if self.domain == "range-azimuth" and self.cfar_kind != "ca":
            raise ValueError(f"cfar_kind {self.cfar_kind!r} needs domain 'integrated'; the "
                             "range-azimuth detector is cell averaging ('ca')")
        return self


class ScatteringConfig(_Frozen):
    """Surface model per material (:mod:`sim2radar.radar.returns` has the equations).

    ``coefficients``: effective-roughness (ER) scattering coefficient ``S`` in [0, 1]
    (Degli-Esposti et al., IEEE TAP 55(1), 2007): a fraction ``S^2`` of the reflected power is
    scattered diffusely, ``1 - S^2`` stays in the specular (physical-optics) component.
    Materials not listed use ``default`` (values: :data:`DEFAULT_SCATTERING_COEFFICIENTS`,
    heuristics).

    ``model``: the diffuse pattern. ``"lambertian"`` (default; ``cos(theta_s) / pi``) or
    ``"directive"``: the ER "directive model" of the same paper, intensity
    ``~ ((1 + cos psi_R) / 2)^alpha_R`` around the specular direction, normalised so the total
    scattered power is ``S^2 |Gamma|^2`` of the power incident on the facet. ``lobe_exponent``
    gives ``alpha_R`` per material (>= 0; 0 = uniform over the half-space), ``lobe_default``
    the rest (values: :data:`DEFAULT_LOBE_EXPONENTS`, heuristics).

    ``slab_thickness_m``: materials listed here reflect as a single homogeneous slab of that
    thickness [m] in air (ITU-R P.2040-3 §3, multiple internal reflections) instead of a
    half-space, e.g. ``{glass: 0.008, plasterboard: 0.0125}``. Empty by default.

    ``transmission``: rays may pass through slab materials (slab transmission coefficient,
    ITU-R P.2040-3 eq. (43b)); one seeded reflect-or-transmit choice per ray and interaction.
    A transmitting object is one slab: the ray leaves through its back face without a second
    interaction. Half-space materials (not in ``slab_thickness_m``) never transmit.
    """

    default: float = Field(0.4, ge=0.0, le=1.0)
    coefficients: dict[str, float] = Field(
        default_factory=lambda: dict(DEFAULT_SCATTERING_COEFFICIENTS)
    )
    slab_thickness_m: dict[str, float] = Field(default_factory=dict)
    model: Literal["lambertian", "directive"] = Field(
        "lambertian", description="diffuse pattern: 'lambertian' or 'directive' (ER model)"
    )
    lobe_exponent: dict[str, float] = Field(default_factory=lambda: dict(DEFAULT_LOBE_EXPONENTS))
    lobe_default: float = Field(4.0, ge=0.0, le=1000.0, description="alpha_R of other materials")
    transmission: bool = Field(False, description="rays pass through slab materials")

    @staticmethod
    def _canonical(name: str) -> str:
        try:
            return get_material(name).name
        except KeyError as exc:  # pydantic needs ValueError to report the field
            raise ValueError(str(exc)) from None

    @field_validator("coefficients")
    @classmethod
    def _check_coefficients(cls, value: dict[str, float]) -> dict[str, float]:
        out = {}
        for name, s in value.items():
            if not 0.0 <= float(s) <= 1.0:
                raise ValueError(f"scattering coefficient for {name!r} must lie in [0, 1], got {s}")
            out[cls._canonical(name)] = float(s)
        return out

    @field_validator("slab_thickness_m")
    @classmethod
    def _check_thickness(cls, value: dict[str, float]) -> dict[str, float]:
        out = {}
        for name, d in value.items():
            if not (math.isfinite(float(d)) and float(d) > 0.0):
                raise ValueError(f"slab thickness for {name!r} must be > 0 [m], got {d}")
            out[cls._canonical(name)] = float(d)
        return out

    @field_validator("lobe_exponent")
    @classmethod
    def _check_lobe(cls, value: dict[str, float]) -> dict[str, float]:
        out = {}
        for name, a in value.items():
            if not (math.isfinite(float(a)) and 0.0 <= float(a) <= 1000.0):
                raise ValueError(f"lobe exponent alpha_R for {name!r} must lie in [0, 1000], "
                                 f"got {a}")
            out[cls._canonical(name)] = float(a)
        return out

    def coefficient(self, material: str) -> float:
        """S for ``material`` (its own entry, else ``default``)."""
        return float(self.coefficients.get(get_material(material).name, self.default))

    def thickness_m(self, material: str) -> float | None:
        """Slab thickness [m] of ``material``, or ``None`` for a half-space."""
        return self.slab_thickness_m.get(get_material(material).name)

    def lobe(self, material: str) -> float:
        """Directive-model lobe exponent ``alpha_R`` of ``material`` (else ``lobe_default``)."""
        return float(self.lobe_exponent.get(get_material(material).name, self.lobe_default))

    def transmits(self, material: str) -> bool:
        """Whether rays may pass through ``material`` (``transmission`` on and a slab)."""
        return bool(self.transmission and self.thickness_m(material) is not None)


#: Simulation fidelity levels a RadarConfig can select (``fidelity``): the Mitsuba ray tracer
#: with coherent range/azimuth/elevation binning (the simulator under test, the paper's), or the
#: signal-level FMCW MIMO simulator (paths -> IF samples per TX/RX pair -> TI-style processing
#: chain; the reference radar that stands in for measured data).
FIDELITIES = ("raytrace", "signal")


class HardwareConfig(_Frozen):
    """Transmitter, receiver and antenna elements: the link budget of the radar.

    Used to derive the receiver noise (``k T B F``) relative to the echo power, for both
    fidelity levels (:mod:`sim2radar.radar.link_budget`). Element patterns are one-way power
    patterns ``cos^q`` in azimuth and elevation with the given -3 dB full widths (``q`` from the
    width), applied on transmit and on receive by the signal-level simulator, which also
    applies the IF chain: a first-order high-pass (``if_highpass_hz``) and the decimation
    filter's band edge (``if_bandwidth_fraction`` of the complex sampling rate).
    """

    tx_power_dbm: float = Field(12.0, ge=-30.0, le=40.0,
                                description="output power per transmitter [dBm]")
    tx_gain_dbi: float = Field(10.0, ge=-10.0, le=40.0, description="TX element gain [dBi]")
    rx_gain_dbi: float = Field(10.0, ge=-10.0, le=40.0, description="RX element gain [dBi]")
    noise_figure_db: float = Field(14.0, ge=0.0, le=40.0, description="receiver noise figure [dB]")
    temperature_k: float = Field(290.0, gt=0.0, description="noise reference temperature [K]")
    system_loss_db: float = Field(0.0, ge=0.0, le=40.0,
                                  description="radome, feed and processing losses [dB]")
    azimuth_hpbw_deg: float = Field(100.0, gt=0.0, le=180.0,
                                    description="element -3 dB beamwidth in azimuth [deg]")
    elevation_hpbw_deg: float = Field(30.0, gt=0.0, le=180.0,
                                      description="element -3 dB beamwidth in elevation [deg]")
    if_highpass_hz: float | None = Field(
        None, gt=0.0, description="IF high-pass corner [Hz] (first order; None: off). "
        "AWR2243 HPF1 options: 175, 235, 350, 700 kHz")
    if_bandwidth_fraction: float = Field(
        0.9, gt=0.0, le=1.0, description="usable IF band as a fraction of the complex sampling "
        "rate: the decimation filter's pass band (flat); beyond it, if_rolloff_db")
    if_rolloff_db: tuple[tuple[float, float], ...] = Field(
        ((1.0, -40.0), (1.1, -60.0)), description="the IF (anti-alias / decimation) filter's "
        "attenuation beyond the pass band: (|beat frequency| / f_adc, gain [dB]) points, gain "
        "linear in dB between them from 0 dB at if_bandwidth_fraction, the last value beyond; "
        "returns past the unambiguous range alias (complex sampling) at that attenuation")
    polarization: Literal["unpolarized", "vertical", "horizontal"] = Field(
        "unpolarized", description="TX and RX element polarisation: 'vertical' / 'horizontal' "
        "(linear, the field along theta-hat / phi-hat of the radar frame, Sionna RT's 'V' / 'H') "
        "track it through every bounce; 'unpolarized' uses the mean TE/TM power per bounce")

    @field_validator("if_rolloff_db")
    @classmethod
    def _check_rolloff(cls, value: tuple[tuple[float, float], ...]) -> tuple:
        f = [float(p[0]) for p in value]
        if any(b <= a for a, b in zip(f, f[1:], strict=False)) or any(
                float(p[1]) > 0.0 for p in value):
            raise ValueError("if_rolloff_db needs increasing frequency fractions and gains <= 0 "
                             f"dB, got {list(value)}")
        return value


class SignalChainConfig(_Frozen):
    """The signal-level simulator's synthesis, impairments and processing chain
    (``fidelity: signal``; TI's cascade MIMO chain, TIDEP-01012, is the model). Owned by
    :mod:`sim2radar.radar.fmcw` (synthesis) and :mod:`sim2radar.radar.processing` (chain);
    see there for every formula and its source.

    Two-element tuples are ``(range, other)``: ``other`` is the azimuth axis for
    ``cfar_domain: range-azimuth`` and the Doppler axis for ``range-doppler``.
    """

    # -- synthesis (sim2radar.radar.fmcw) ------------------------------------------------
    synthesis: Literal["time", "frequency", "narrowband"] = Field(
        "frequency", description="'time': every IF sample of every path evaluated directly "
        "(the reference); 'frequency': each path's tone gridded per channel onto an "
        "oversampled spectrum and inverse-FFT'd (NUFFT; P x C x 7 instead of P x C x N_adc "
        "operations), equal within 0.1 dB on a point target; 'narrowband': one tone per path "
        "with exact per-channel phases, Doppler by a slow-time NUFFT (no range walk across the "
        "aperture or the frame; sim2radar.radar.fmcw says how large that is)")
    doppler: Literal["integrated", "full"] = Field(
        "integrated", description="'integrated': no per-chirp synthesis, the Doppler-windowed "
        "coherent sum over chirps (the zero-Doppler bin; static scenes); 'full': every chirp, "
        "Doppler FFT, TDM phase compensation")
    tx_order: tuple[int, ...] | None = Field(
        None, description="TDM firing order within a loop: 0-based indices into "
        "tx_antennas_half_wl (None: list order)")
    adc_bits: int | None = Field(None, ge=2, le=24, description="ADC quantisation (None: off)")
    adc_full_scale_db: float = Field(
        60.0, ge=0.0, le=140.0, description="ADC full scale per I/Q rail above the thermal-noise "
        "rms per rail [dB] (the IF gain setting; signals beyond it clip)")
    tx_rx_leakage_db: float | None = Field(
        None, le=0.0, description="TX->RX coupling leakage [dB re the transmit power] (None: off)")
    channel_gain_error_db: float = Field(0.0, ge=0.0, le=10.0,
                                         description="per-virtual-channel gain error std [dB]")
    channel_phase_error_deg: float = Field(0.0, ge=0.0, le=180.0,
                                           description="per-virtual-channel phase error std [deg]")
    mutual_coupling_db: float | None = Field(
        None, le=0.0, description="coupling between elements lambda/2 apart [dB] (None: off)")
    impairment_seed: int = Field(0, description="seed of the fixed per-channel errors (a board's "
                                 "calibration residue, the same every frame)")
    # -- processing (sim2radar.radar.processing) ------------------------------------------
    range_window: Literal["none", "hann", "hanning", "hamming", "blackman"] = Field(
        "hann", description="range FFT window ('hanning': MATLAB's symmetric hanning(N) without "
        "zero end points, TI's cascade chain; 'hann': the DFT-even one)")
    range_dc_removal: bool = Field(
        False, description="subtract each chirp's mean over its samples, per channel, before "
        "the range window (TI's rangeProcCascade, always on there)")
    doppler_window: Literal["none", "hann", "hanning", "hamming", "blackman"] = "hann"
    doppler_clutter_removal: bool = Field(
        False, description="subtract each range bin's mean over the chirps, per channel, after "
        "the Doppler window (TI's DopplerProcClutterRemove, off by default there): removes what "
        "does not move relative to the radar")
    azimuth_window: Literal["none", "hann", "hanning", "hamming", "blackman"] = "none"
    azimuth_fft_size: int = Field(256, ge=16, le=4096,
                                  description="zero-padded azimuth FFT length [bins]")
    elevation_fft_size: int = Field(256, ge=8, le=4096,
                                    description="zero-padded elevation FFT length [bins]")
    virtual_duplicates: Literal["first", "average"] = Field(
        "average", description="virtual channels sharing an array position: keep the first in "
        "TX firing order (TI's DOA_beamformingFFT_2D, MATLAB unique) or average them")
    cfar_kind: Literal["ca", "caso", "os"] = Field(
        "ca", description="'ca' (cell averaging), 'caso' (smallest of the two sides' means, TI's "
        "CFAR_CASO; range-doppler only) or 'os' (ordered statistic)")
    cfar_domain: Literal["range-azimuth", "range-doppler"] = Field(
        "range-azimuth", description="'range-doppler': TI's cascade point path (one CFAR pass "
        "along range on every Doppler column of the map summed over virtual channels, one along "
        "Doppler on the range hits, both needed; angles only at the detections); "
        "'range-azimuth': a 2-D CFAR on each Doppler bin's range-azimuth map (TI's display "
        "heatmap, not its point path)")
    cfar_guard_cells: tuple[int, int] = Field((2, 2), description="guard cells each side [bins]")
    cfar_training_cells: tuple[int, int] = Field((8, 4),
                                                 description="training cells each side [bins]")
    cfar_threshold: tuple[float, float] | None = Field(
        None, description="linear threshold factors (range pass, other axis) - TI's K0; null: "
        "designed from cfar_pfa")
    cfar_pfa: float = Field(1e-4, gt=0.0, lt=0.5, description="design false-alarm rate per cell "
                            "(when cfar_threshold is null)")
    cfar_discard_range_bins: tuple[int, int] = Field(
        (0, 0), description="range-doppler: first / last range bins never tested (TI's "
        "discardCellLeft / discardCellRight); the range pass pads its ends as TI does")
    cfar_os_rank: float = Field(0.75, gt=0.0, le=1.0,
                                description="OS-CFAR rank as a fraction of the training cells")
    angle_sidelobe_db: float = Field(
        1.0, ge=0.0, le=60.0, description="range-doppler: azimuth peaks of a detection whose "
        "magnitude is >= max * 10^(-x/10) are points (TI's sidelobeLevel_dB_azim, applied to "
        "magnitudes as TI does)")
    elevation_sidelobe_db: float = Field(
        0.0, ge=0.0, le=60.0, description="the same rule for elevation peaks per azimuth peak "
        "(TI's sidelobeLevel_dB_elev: 0 = the maximum only)")
    angle_peak_hysteresis_db: float = Field(
        0.2, gt=0.0, le=10.0, description="hysteresis of the angle peak search [dB] (TI's "
        "gamma = 10^(0.2/10))")
    azimuth_gate_deg: float | None = Field(
        None, gt=0.0, le=90.0, description="points at |azimuth| beyond this are dropped [deg] "
        "(TI: 80); null: half the azimuth FOV")
    elevation_gate_deg: float | None = Field(
        None, gt=0.0, le=90.0, description="points at |elevation| beyond this are dropped [deg] "
        "(TI: 20); null: half the elevation FOV")
    interpolate: bool = Field(
        True, description="refine range, Doppler and angles between bins (parabola through log "
        "powers); false: bin positions, as TI's chain reports them")
    doppler_sidelobe_db: float = Field(
        20.0, gt=0.0, le=80.0, description="full Doppler, range-azimuth: a point's Doppler bin "
        "must be within this many dB of the strongest of its range-azimuth cell (the Hann "
        "window's -31 dB Doppler sidelobes of strong echoes are not targets) [dB]")
    min_range_m: float = Field(
        0.0, ge=0.0, description="no detections nearer than this [m] (TX->RX leakage and the "
        "IF high-pass region; TI's chains skip the first range bins likewise)")
    peak_grouping: bool = Field(True, description="keep only local maxima (3x3, or 3x3x3 with "
                                "Doppler; range-doppler: 3x3 on the range-Doppler map)")
    max_points: int | None = Field(None, ge=1, description="keep the strongest N points")

    @model_validator(mode="after")
    def _check_chain(self) -> SignalChainConfig:
        if self.cfar_kind == "caso" and self.cfar_domain != "range-doppler":
            raise ValueError("cfar_kind 'caso' is TI's 1-D pass of the range-doppler domain; "
                             "use 'ca' or 'os' with cfar_domain 'range-azimuth'")
        if self.cfar_threshold is not None and min(self.cfar_threshold) <= 0:
            raise ValueError(f"cfar_threshold factors must be > 0, got {self.cfar_threshold}")
        if min(self.cfar_discard_range_bins) < 0:
            raise ValueError("cfar_discard_range_bins must be >= 0, got "
                             f"{self.cfar_discard_range_bins}")
        return self

    @field_validator("cfar_guard_cells")
    @classmethod
    def _check_guard(cls, value: tuple[int, int]) -> tuple[int, int]:
        if min(value) < 0:
            raise ValueError(f"guard cells must be >= 0, got {value}")
        return value

    @field_validator("cfar_training_cells")
    @classmethod
    def _check_training(cls, value: tuple[int, int]) -> tuple[int, int]:
        if min(value) < 0 or max(value) < 1:
            raise ValueError(f"training cells must be >= 0 with at least one > 0, got {value}")
        return value

    @field_validator("tx_order")
    @classmethod
    def _check_tx_order(cls, value: tuple[int, ...] | None) -> tuple[int, ...] | None:
        if value is not None and (sorted(value) != list(range(len(value)))):
            raise ValueError(f"tx_order must be a permutation of 0..N_tx-1, got {list(value)}")
        return value


#: The largest ADC cube of one frame [bytes] (complex64, virtual channels x chirps x samples):
#: checked when a config is read, before a frame allocates it (TI's cascade at 128 chirps: 50 MB).
MAX_ADC_CUBE_BYTES = 2 * 2**30


class RadarConfig(_Frozen):
    """A validated FMCW MIMO radar description (all lengths [m], frequencies [Hz], angles [deg]).

    Attributes
    ----------
    name : str
        Preset or user name.
    start_frequency_hz : float
        Chirp start frequency [Hz].
    bandwidth_hz : float
        Swept (sampled) bandwidth B [Hz].
    adc_samples : int
        ADC samples per chirp = number of range bins.
    adc_sample_rate_hz : float
        Complex ADC sample rate [Hz].
    chirp_slope_hz_per_s : float | None
        Chirp slope S [Hz/s]; derived as ``B f_s / N`` when omitted; when given it must agree.
    n_chirps : int
        Chirps per frame (per TX); stored for Doppler-capable backends.
    tx_antennas_half_wl, rx_antennas_half_wl : list of (azimuth, elevation)
        Antenna positions in units of lambda/2.
    azimuth_fov_deg, elevation_fov_deg : float
        Full field of view [deg], in (0, 180].
    ray_spacing_deg : float
        Angular spacing of the ray grid [deg] (the ray density).
    max_bounces : int
        Specular bounces followed (1 = direct returns only).
    azimuth_bin_deg, elevation_bin_deg : float | None
        Angular bin widths of the cube at boresight [deg]; default the array's resolution.
        Bins are uniform in ``u = sin(angle)`` and centred on boresight (an odd count), so a bin
        spans ``width / cos(angle)`` off boresight, as the array's resolution does.
    """

    name: str = "custom"
    description: str = ""
    start_frequency_hz: float = Field(gt=0)
    bandwidth_hz: float = Field(gt=0)
    adc_samples: int = Field(gt=1, le=1 << 16)
    adc_sample_rate_hz: float = Field(gt=0)
    chirp_slope_hz_per_s: float | None = Field(None, gt=0)
    n_chirps: int = Field(1, ge=1)
    tx_antennas_half_wl: list[tuple[float, float]] = Field(min_length=1)
    rx_antennas_half_wl: list[tuple[float, float]] = Field(min_length=1)
    azimuth_fov_deg: float = Field(gt=0, le=180)
    elevation_fov_deg: float = Field(gt=0, le=180)
    azimuth_bin_deg: float | None = Field(None, gt=0)
    elevation_bin_deg: float | None = Field(None, gt=0)
    ray_spacing_deg: float = Field(0.2, gt=0.005, le=10.0)
    max_bounces: int = Field(2, ge=1, le=8)
    chirp_idle_time_s: float = Field(5e-6, ge=0.0, description="idle time between chirps [s]")
    adc_start_time_s: float = Field(6e-6, ge=0.0,
                                    description="ramp start to first ADC sample [s]")
    fidelity: str = Field("raytrace", description="one of FIDELITIES")
    detection: DetectionConfig = Field(default_factory=DetectionConfig)
    scattering: ScatteringConfig = Field(default_factory=ScatteringConfig)
    hardware: HardwareConfig = Field(default_factory=HardwareConfig)
    signal: SignalChainConfig = Field(default_factory=SignalChainConfig)

    @model_validator(mode="after")
    def _check_consistency(self) -> RadarConfig:
        derived = self.bandwidth_hz * self.adc_sample_rate_hz / self.adc_samples
        if self.chirp_slope_hz_per_s is not None:
            if abs(self.chirp_slope_hz_per_s - derived) > 0.01 * derived:
                raise ValueError(
                    f"chirp_slope_hz_per_s={self.chirp_slope_hz_per_s:.6g} disagrees with "
                    f"bandwidth_hz * adc_sample_rate_hz / adc_samples = {derived:.6g} (>1 %); "
                    "fix one of them or omit chirp_slope_hz_per_s to derive it"
                )
        if self.bandwidth_hz >= self.start_frequency_hz:
            raise ValueError("bandwidth_hz must be smaller than start_frequency_hz")
        if self.fidelity not in FIDELITIES:
            raise ValueError(f"fidelity must be one of {FIDELITIES}, got {self.fidelity!r}")
        cube = self.n_tx * self.n_rx * self.n_chirps * self.adc_samples * 8  # complex64
        if cube > MAX_ADC_CUBE_BYTES:
            raise ValueError(
                f"n_chirps ({self.n_chirps}) x virtual channels ({self.n_tx} TX x {self.n_rx} "
                f"RX) x adc_samples ({self.adc_samples}) makes a {cube / 2**30:.1f} GiB ADC cube "
                f"per frame, more than the {MAX_ADC_CUBE_BYTES / 2**30:.0f} GiB bound; lower "
                "n_chirps (TI's cascade uses 64-256)")
        return self

    # -- derived values -----------------------------------------------------------------
    @property
    def slope_hz_per_s(self) -> float:
        """Chirp slope S [Hz/s] (given, or ``B f_s / N_adc``)."""
        if self.chirp_slope_hz_per_s is not None:
            return float(self.chirp_slope_hz_per_s)
        return self.bandwidth_hz * self.adc_sample_rate_hz / self.adc_samples

    @property
    def center_frequency_hz(self) -> float:
        """Centre of the swept band [Hz]; sets the wavelength used for phases."""
        return self.start_frequency_hz + 0.5 * self.bandwidth_hz

    @property
    def wavelength_m(self) -> float:
        """Wavelength at the centre frequency, ``c / f_c`` [m]."""
        return SPEED_OF_LIGHT_M_S / self.center_frequency_hz

    @property
    def range_resolution_m(self) -> float:
        """FMCW range resolution ``c / (2 B)`` [m]."""
        return SPEED_OF_LIGHT_M_S / (2.0 * self.bandwidth_hz)

    @property
    def max_range_m(self) -> float:
        """Maximum unambiguous range ``f_s c / (2 S)`` [m] (complex sampling)."""
        return self.adc_sample_rate_hz * SPEED_OF_LIGHT_M_S / (2.0 * self.slope_hz_per_s)

    @property
    def sampling_time_s(self) -> float:
        """ADC sampling window per chirp ``N_adc / f_s`` [s]."""
        return self.adc_samples / self.adc_sample_rate_hz

    @property
    def range_rate_resolution_mps(self) -> float:
        """Doppler bin width in range rate, ``lambda / (2 N_chirps T_loop)`` [m/s] with the TDM
        loop ``T_loop = N_tx * chirp_period_s`` (TI SWRA553, velocity-resolution section)."""
        return self.wavelength_m / (2.0 * self.n_chirps * self.n_tx * self.chirp_period_s)

    @property
    def chirp_period_s(self) -> float:
        """One chirp slot: idle + ramp up to the first sample + sampling window [s] (the
        interval between consecutive TX slots in TDM-MIMO)."""
        return self.chirp_idle_time_s + self.adc_start_time_s + self.sampling_time_s

    @property
    def n_tx(self) -> int:
        return len(self.tx_antennas_half_wl)

    @property
    def n_rx(self) -> int:
        return len(self.rx_antennas_half_wl)

    @property
    def n_range_bins(self) -> int:
        """Range bins in the cube (= ADC samples)."""
        return int(self.adc_samples)

    @cached_property
    def virtual_array_half_wl(self) -> np.ndarray:
        """(N_tx * N_rx, 2) float64 — virtual antenna positions [lambda/2]: TX + RX sums."""
        tx = np.asarray(self.tx_antennas_half_wl, dtype=np.float64).reshape(-1, 2)
        rx = np.asarray(self.rx_antennas_half_wl, dtype=np.float64).reshape(-1, 2)
        return (tx[:, None, :] + rx[None, :, :]).reshape(-1, 2)

    @property
    def n_virtual(self) -> int:
        """Number of virtual channels (N_tx * N_rx)."""
        return len(self.virtual_array_half_wl)

    @staticmethod
    def _aperture_elements(positions: np.ndarray) -> float:
        """Filled-aperture length in lambda/2 units: span + 1 element."""
        unique = np.unique(np.round(positions, 6))
        return float(unique.max() - unique.min() + 1.0)

    @property
    def n_azimuth_virtual(self) -> int:
        """Distinct azimuth positions of the virtual array."""
        return int(len(np.unique(np.round(self.virtual_array_half_wl[:, 0], 6))))

    @property
    def azimuth_resolution_rad(self) -> float:
        """-3 dB beamwidth ``0.886 lambda / D_az`` [rad], ``D_az = N_az lambda/2``."""
        return 0.886 * 2.0 / self._aperture_elements(self.virtual_array_half_wl[:, 0])

    @property
    def elevation_resolution_rad(self) -> float:
        """-3 dB beamwidth ``0.886 lambda / D_el`` [rad] (capped at pi)."""
        return min(math.pi, 0.886 * 2.0 / self._aperture_elements(self.virtual_array_half_wl[:, 1]))

    @property
    def azimuth_fov_rad(self) -> float:
        return math.radians(self.azimuth_fov_deg)

    @property
    def elevation_fov_rad(self) -> float:
        return math.radians(self.elevation_fov_deg)

    @staticmethod
    def _u_bins(fov_rad: float, width_u: float) -> np.ndarray:
        """Bin centres ``k * width_u`` (k = -K..K) covering ``|u| <= sin(fov / 2)``, ``|u| <= 1``."""
        u_max = math.sin(min(0.5 * fov_rad, 0.5 * math.pi))
        k = max(0, math.ceil(u_max / width_u - 0.5 - 1e-9))
        k = min(k, math.floor(1.0 / width_u + 1e-9))
        return np.arange(-k, k + 1, dtype=np.float64) * width_u

    @property
    def azimuth_bin_u(self) -> float:
        """Azimuth bin width in ``u = sin(azimuth)`` [-] (the boresight width in rad)."""
        if self.azimuth_bin_deg:
            return math.radians(self.azimuth_bin_deg)
        return self.azimuth_resolution_rad

    @property
    def elevation_bin_u(self) -> float:
        """Elevation bin width in ``u = sin(elevation)`` [-] (the boresight width in rad)."""
        if self.elevation_bin_deg:
            return math.radians(self.elevation_bin_deg)
        return self.elevation_resolution_rad

    @property
    def azimuth_bins_u(self) -> np.ndarray:
        """(n_az,) float64 — azimuth bin centres in ``u = cos(el) sin(az)`` [-] (+ = left),
        uniform, one centred on boresight. A beam of the virtual array has a constant width in
        ``u``, so these bins follow its ``1 / cos`` broadening off boresight."""
        return self._u_bins(self.azimuth_fov_rad, self.azimuth_bin_u)

    @property
    def elevation_bins_u(self) -> np.ndarray:
        """(n_el,) float64 — elevation bin centres in ``u = sin(el)`` [-] (+ = up), uniform,
        one centred on boresight."""
        return self._u_bins(self.elevation_fov_rad, self.elevation_bin_u)

    @property
    def n_azimuth_bins(self) -> int:
        """Azimuth bins covering the FOV (odd: one centred on boresight)."""
        return len(self.azimuth_bins_u)

    @property
    def n_elevation_bins(self) -> int:
        """Elevation bins covering the FOV (odd: one centred on boresight)."""
        return len(self.elevation_bins_u)

    @property
    def range_bins_m(self) -> np.ndarray:
        """(n_range,) float32 — range bin centres ``i * dR`` [m]."""
        return (np.arange(self.n_range_bins) * self.range_resolution_m).astype(np.float32)

    @property
    def azimuth_bins_rad(self) -> np.ndarray:
        """(n_az,) float32 — azimuth bin centres ``arcsin(u)`` [rad] (+ = left; at el = 0)."""
        return np.arcsin(self.azimuth_bins_u).astype(np.float32)

    @property
    def elevation_bins_rad(self) -> np.ndarray:
        """(n_el,) float32 — elevation bin centres ``arcsin(u)`` [rad] (+ = up)."""
        return np.arcsin(self.elevation_bins_u).astype(np.float32)

    @property
    def ray_grid_shape(self) -> tuple[int, int]:
        """(n_azimuth_rays, n_elevation_rays) of the ray grid."""
        return (
            max(1, math.ceil(self.azimuth_fov_deg / self.ray_spacing_deg)),
            max(1, math.ceil(self.elevation_fov_deg / self.ray_spacing_deg)),
        )

    @property
    def n_rays(self) -> int:
        """Primary rays per frame."""
        a, e = self.ray_grid_shape
        return a * e

    # -- serialisation ------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Resolved, JSON-able configuration (the slope filled in); stable for hashing."""
        d = self.model_dump(mode="json")
        d["chirp_slope_hz_per_s"] = self.slope_hz_per_s
        return d

    def derived(self) -> dict[str, float]:
        """Derived values for reports (JSON-able)."""
        return {
            "center_frequency_hz": self.center_frequency_hz,
            "wavelength_m": self.wavelength_m,
            "range_resolution_m": self.range_resolution_m,
            "max_range_m": self.max_range_m,
            "azimuth_resolution_deg": math.degrees(self.azimuth_resolution_rad),
            "elevation_resolution_deg": math.degrees(self.elevation_resolution_rad),
            "n_virtual": self.n_virtual,
            "n_azimuth_virtual": self.n_azimuth_virtual,
            "cube_shape": (self.n_range_bins, self.n_azimuth_bins, self.n_elevation_bins),
            "n_rays": self.n_rays,
        }

    def content_hash(self) -> str:
        """SHA-256 (hex, 16 chars) of :meth:`to_dict` with sorted keys."""
        blob = json.dumps(self.to_dict(), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]

    def with_updates(self, **changes: Any) -> RadarConfig:
        """A validated copy with some fields changed (nested configs as dicts allowed)."""
        data = self.model_dump()
        for key, value in changes.items():
            if key in ("detection", "scattering", "hardware", "signal") and isinstance(value, dict):
                data[key] = {**data[key], **value}
            else:
                data[key] = value
        return RadarConfig.model_validate(data)


def preset_names() -> list[str]:
    """Names of the built-in presets (``presets/*.yaml`` stems), sorted."""
    return sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))


def _format_validation_error(source: str, exc: ValidationError) -> str:
    lines = [f"invalid radar config {source}:"]
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"]) or "(root)"
        value = err.get("input")
        shown = "" if isinstance(value, dict) else f" (got {short_repr(value)})"
        lines.append(f"  field '{loc}': {short_text(err['msg'])}{shown}")
    return "\n".join(lines)


def load_radar_config(name_or_path: str | Path | RadarConfig, **overrides: Any) -> RadarConfig:
    """Load a preset by name (see :func:`preset_names`) or a YAML file, then validate.

    Parameters
    ----------
    name_or_path : str, Path or RadarConfig
        ``"ti-mmwcas"``, ``"ti-iwr1843"``, a path to a YAML file, or an existing config.
    **overrides
        Field values replacing those of the file (e.g. ``max_bounces=1``).

    Raises
    ------
    RadarConfigError
        Unknown preset (lists the known ones), unreadable YAML, or invalid fields (each named).
    """
    if isinstance(name_or_path, RadarConfig):
        return name_or_path.with_updates(**overrides) if overrides else name_or_path
    text = str(name_or_path)
    path = Path(text)
    if not path.suffix and (PRESET_DIR / f"{text}.yaml").is_file():
        path = PRESET_DIR / f"{text}.yaml"
    if not path.is_file():
        raise RadarConfigError(
            f"radar config {text!r} is neither a preset nor a file; "
            f"presets: {', '.join(preset_names())}"
        )
    doc = read_yaml_mapping(path, error=RadarConfigError, expect="a mapping of radar fields")
    doc = {**doc, **overrides}
    try:
        return RadarConfig.model_validate(doc)
    except ValidationError as exc:
        raise RadarConfigError(_format_validation_error(str(path), exc)) from None
