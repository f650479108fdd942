"""Signal-level reference radar benchmark: seconds per frame and peak memory vs path count.

Synthetic corridor path sets (diffuse points on walls, floor, ceiling and an end wall, 20 %
two-bounce paths whose departure and arrival points differ) at the ``ti-mmwcas-reference``
preset (12 TX x 16 RX = 192 channels, 256 samples, integrated Doppler). Figures: synthesis,
processing and total seconds per frame (median of the timed frames after one warm-up frame),
the torch device, and the process's peak resident memory (and its growth per path count);
then one frame of the full chirp cube (``doppler: full``, static scene).

    python -m benchmarks signal
"""

from __future__ import annotations

import math
import resource
import statistics
import time

import numpy as np

from sim2radar.radar import load_radar_config
from sim2radar.radar.paths import PATH_KINDS, PathSet
from sim2radar.radar.signal import simulate_signal_frame

PATH_COUNTS = (10_000, 30_000, 50_000)
N_FRAMES = 3


def synthetic_paths(n_paths: int, seed: int = 0) -> PathSet:
    """A corridor-like PathSet: ``n_paths`` diffuse returns, 80 % single-, 20 % two-bounce.

    Points lie on the walls (y = +-1.2 m), floor (z = -1.0 m), ceiling (z = 1.5 m) and an end
    wall (x = 8 m) within 0.5-8 m; each has RCS ~ Exp(mean 1e-3 m^2) and a uniform phase.
    """
    rng = np.random.default_rng(seed)
    surf = rng.integers(0, 5, n_paths)
    x = rng.uniform(0.5, 8.0, n_paths)
    y = rng.uniform(-1.2, 1.2, n_paths)
    z = rng.uniform(-1.0, 1.5, n_paths)
    y = np.where(surf == 0, 1.2, np.where(surf == 1, -1.2, y))
    z = np.where(surf == 2, -1.0, np.where(surf == 3, 1.5, z))
    x = np.where(surf == 4, 8.0, x)
    pts = np.column_stack([x, y, z])
    base = PathSet.point_targets(pts, rng.exponential(1e-3, n_paths),
                                 phase_rad=rng.uniform(0, 2 * math.pi, n_paths))
    two = rng.random(n_paths) < 0.2
    arr = pts.copy()
    arr[two] = pts[rng.permutation(np.nonzero(two)[0])]  # arrive from another point
    inner = np.where(two, np.linalg.norm(arr - pts, axis=1), 0.0)
    length = np.linalg.norm(pts, axis=1) + inner + np.linalg.norm(arr, axis=1)
    amp = base.amplitude * np.where(two, 0.3, 1.0)
    return PathSet(amplitude=amp, path_length_m=length, departure_point_m=pts,
                   arrival_point_m=arr, range_rate_mps=np.zeros(n_paths),
                   n_interactions=np.where(two, 2, 1).astype(np.int8),
                   kind=np.full(n_paths, PATH_KINDS["diffuse"], np.int8))


def _peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main() -> dict:
    radar = load_radar_config("ti-mmwcas-reference")
    simulate_signal_frame(synthetic_paths(1000, 99), radar, seed=0)  # warm-up (imports, caches)
    out: dict = {}
    for n in PATH_COUNTS:
        paths = synthetic_paths(n, seed=n)
        rss0 = _peak_rss_mib()
        frames = []
        for i in range(N_FRAMES + 1):
            t0 = time.perf_counter()
            frame = simulate_signal_frame(paths, radar, seed=i)
            wall = time.perf_counter() - t0
            if i:
                frames.append((frame.stats["seconds_if_total"],
                               frame.stats["seconds_processing"], wall))
        synth, proc, total = (statistics.median(c) for c in zip(*frames, strict=True))
        out[n] = {
            "seconds_synthesis": round(synth, 3),
            "seconds_processing": round(proc, 3),
            "seconds_total": round(total, 3),
            "points": frame.n_points,
            "device": frame.stats["device"],
            "peak_rss_growth_mib": round(_peak_rss_mib() - rss0, 1),
            "peak_rss_mib": round(_peak_rss_mib(), 1),
        }
        print(f"{n:>6} paths: synthesis {synth:.3f} s, processing {proc:.3f} s, total "
              f"{total:.3f} s per frame, {frame.n_points} points, device {frame.stats['device']}, "
              f"peak RSS {out[n]['peak_rss_mib']:.0f} MiB (+{out[n]['peak_rss_growth_mib']:.0f})")
    # the full chirp cube (64 loops, Doppler FFT, TDM compensation, CFAR per Doppler bin)
    full = radar.with_updates(signal={"doppler": "full"})
    paths = synthetic_paths(PATH_COUNTS[0], seed=1)
    simulate_signal_frame(paths, full, seed=0)
    t0 = time.perf_counter()
    frame = simulate_signal_frame(paths, full, seed=1)
    wall = time.perf_counter() - t0
    out[f"full_doppler_{PATH_COUNTS[0]}"] = {
        "seconds_synthesis": round(frame.stats["seconds_if_total"], 3),
        "seconds_processing": round(frame.stats["seconds_processing"], 3),
        "seconds_total": round(wall, 3),
        "points": frame.n_points,
    }
    print(f"{PATH_COUNTS[0]:>6} paths, doppler: full (static): synthesis "
          f"{frame.stats['seconds_if_total']:.3f} s, processing "
          f"{frame.stats['seconds_processing']:.3f} s, total {wall:.3f} s, "
          f"peak RSS {_peak_rss_mib():.0f} MiB")
    return out


if __name__ == "__main__":
    main()
