"""The signal-level FMCW MIMO simulator (``fidelity: signal``): paths -> IF -> point cloud.

The project's *reference radar* (the labelled proxy for measured data, never called real):
:func:`simulate_signal_frame` synthesises the IF samples of every TX/RX pair from a
:class:`~sim2radar.radar.paths.PathSet` (:mod:`sim2radar.radar.fmcw`) and runs TI's cascade
processing chain on them (:mod:`sim2radar.radar.processing`: TI's 4-chip cascade MIMO
example's detection chain)::

    from sim2radar.radar import load_radar_config
    from sim2radar.radar.paths import PathSet
    from sim2radar.radar.signal import simulate_signal_frame

    radar = load_radar_config("ti-mmwcas-reference")
    paths = PathSet.point_targets([[4.0, 0.5, 0.0]], rcs_m2=1.0)
    frame = simulate_signal_frame(paths, radar, seed=0)
    frame.points      # (N, 5) float32: x, y, z [m], intensity [dB], radial velocity [m/s]

Torch runs the heavy parts on :func:`sim2radar.hardware.torch_device` (CUDA when present).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from sim2radar.radar.config import RadarConfig
from sim2radar.radar.fmcw import synthesize_if
from sim2radar.radar.paths import PathSet
from sim2radar.radar.processing import process_if

__all__ = ["SignalFrame", "simulate_signal_frame", "POINT_COLUMNS"]

#: Columns of :attr:`SignalFrame.points`.
POINT_COLUMNS = ("x", "y", "z", "intensity_db", "doppler_mps")


@dataclasses.dataclass(frozen=True, eq=False)
class SignalFrame:
    """One frame of the signal-level simulator.

    Attributes
    ----------
    points : (N, 5) float32 — x, y, z [m] (radar frame: x forward, y left, z up), intensity
        [dB] (``10 log10(4 pi |a|^2)``, the ray tracer's scale; see
        :mod:`sim2radar.radar.processing`), radial velocity [m/s] (positive = receding);
        strongest first.
    stats : dict — seconds per stage (``seconds_synthesis``, ``seconds_if_total``,
        ``seconds_range_doppler_fft``, ``seconds_azimuth_fft``, ``seconds_cfar_and_angles``,
        ``seconds_points``, ``seconds_processing``, ``seconds_total``), counts (``n_paths``,
        ``n_paths_synthesised``, ``n_paths_beyond_if_band``, ``moving_paths``,
        ``n_detections``), noise (``noise_power_w`` per IF sample, ``noise_floor_db`` per
        range-Doppler-azimuth cell on the intensity scale), the CFAR design (range-doppler:
        ``cfar_alpha_range_db``, ``cfar_design_pfa_range``, ``cfar_n_eff_range`` and the
        ``_doppler`` ones, ``cfar_looks``; range-azimuth: ``cfar_alpha_db``,
        ``cfar_design_pfa``, ``cfar_n_train``, ``cfar_n_eff``), ``seed``, ``device``.
    range_m : (n_range,) float32 — range-bin centres [m].
    azimuth_sin : (n_az,) float32 — ``sin(az) cos(el)`` of the azimuth bins in the FOV [-].
    range_azimuth_db : (n_range, n_az) float32 or None — range-azimuth map (max over
        Doppler), intensity scale [dB]; None with ``heatmap=False``.
    range_doppler_db : (n_range, n_doppler) float32 — the map summed over virtual channels that
        TI's CFAR runs on [dB re 1 W per sample^2].
    if_samples : (n_slow, N_tx, N_rx, N_adc) complex64 or None — IF samples [sqrt(W)]
        (``return_cubes=True``; ``n_slow`` = 1 for ``doppler: integrated``).
    range_doppler_cube : (n_doppler, N_tx, N_rx, n_range) complex64 or None — after range and
        Doppler FFT and TDM compensation (``return_cubes=True``).
    """

    points: np.ndarray
    stats: dict[str, Any]
    range_m: np.ndarray
    azimuth_sin: np.ndarray
    range_azimuth_db: np.ndarray | None
    range_doppler_db: np.ndarray | None = None
    if_samples: np.ndarray | None = None
    range_doppler_cube: np.ndarray | None = None

    @property
    def n_points(self) -> int:
        return int(len(self.points))


def simulate_signal_frame(
    paths: PathSet,
    radar: RadarConfig,
    *,
    seed: int | None = None,
    return_cubes: bool = False,
    device: Any = None,
    heatmap: bool = True,
) -> SignalFrame:
    """Simulate one frame of the signal-level radar.

    Parameters
    ----------
    paths : PathSet — propagation paths in the radar frame (tracer normalisation).
    radar : RadarConfig — normally ``fidelity: signal`` (any preset works: the ``signal`` and
        ``hardware`` sections have defaults).
    seed : int or None — thermal-noise seed; None: no noise (deterministic; CFAR then runs
        on the expected power, signal + known noise per cell).
    return_cubes : bool — also return the IF samples and the range-Doppler cube.
    device : torch device, optional — default :func:`sim2radar.hardware.torch_device`.
    heatmap : bool — also form the range-azimuth map (``range_azimuth_db``) over every cell;
        the factory's frames, which keep only the points, pass False
        (:func:`~sim2radar.radar.processing.process_if`).

    Returns
    -------
    SignalFrame
    """
    t0 = time.perf_counter()
    cube = synthesize_if(paths, radar, seed=seed, device=device)
    t1 = time.perf_counter()
    result = process_if(cube, radar, noise_free=seed is None, keep_cube=return_cubes,
                        heatmap=heatmap)
    t2 = time.perf_counter()
    stats = {**cube.stats, **result.stats, "seed": seed, "seconds_processing": t2 - t1,
             "seconds_total": t2 - t0}
    if_samples = rd_cube = None
    if return_cubes:
        if_samples = cube.samples.cpu().numpy()
        rd_cube = result.range_doppler_cube.cpu().numpy()
    return SignalFrame(
        points=result.points,
        stats=stats,
        range_m=result.range_m,
        azimuth_sin=result.azimuth_sin,
        range_azimuth_db=result.range_azimuth_db,
        range_doppler_db=result.range_doppler_db,
        if_samples=if_samples,
        range_doppler_cube=rd_cube,
    )
