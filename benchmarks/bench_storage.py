"""Artifact store and simulate-flow overhead.

    python -m benchmarks storage

Figures: radar_points write (validate + provenance + atomic publish) and read (+ decode) for a
100-frame x 2000-point table; the cost of the skip path (hash scene files, compute keys, two
exists checks); the built-in demo scene computed vs cached through the ``simulate`` job's
driver with a plain runner (:func:`sim2radar.tasks.radar.simulate_scenes` +
:class:`~sim2radar.tasks.runner.PlainRunner`, what ``--no-prefect`` runs); and the same through
the Prefect flow (:func:`sim2radar.flows.simulate.simulate_dataset`; its first call includes
starting the ephemeral Prefect API).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np


def _median_s(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> dict:
    tmp = Path(tempfile.mkdtemp(prefix="bench-storage-"))
    os.environ.setdefault("PREFECT_HOME", str(tmp / "prefect-home"))
    os.environ.setdefault("PREFECT_LOGGING_LEVEL", "WARNING")
    os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")

    from sim2radar.scenes import demo_scene_paths
    from sim2radar.storage import (
        ArtifactStore,
        content_key,
        radar_frames_from_table,
        radar_frames_to_table,
    )
    from sim2radar.tasks.radar import SimulateRequest, scene_keys, simulate_scenes
    from sim2radar.tasks.runner import PlainRunner

    out: dict = {}
    # -- store throughput ------------------------------------------------------------------
    rng = np.random.default_rng(0)
    n_frames, n_points = 100, 2000
    table = radar_frames_to_table(
        scene_id="bench",
        radar_to_world=[np.eye(4)] * n_frames,
        points=[rng.normal(size=(n_points, 4)).astype(np.float32) for _ in range(n_frames)],
        boxes=[rng.normal(size=(3, 7)) for _ in range(n_frames)],
    )
    store = ArtifactStore(tmp / "store")
    keys = iter(content_key(stage="radar_points", stage_version=1, config={"i": i}) for i in range(10_000))
    write_s = _median_s(lambda: store.write("radar_points", next(keys), table, provenance={"seed": 0}), 5)
    key = store.keys("radar_points")[0]
    read_s = _median_s(lambda: radar_frames_from_table(store.read("radar_points", key)), 5)
    size_mb = os.path.getsize(store.path("radar_points", key)) / 1e6
    out["write_100x2000_s"] = write_s
    out["read_decode_100x2000_s"] = read_s
    out["file_mb"] = size_mb
    out["write_frames_per_s"] = n_frames / write_s
    out["read_frames_per_s"] = n_frames / read_s
    mem = ArtifactStore(f"memory://bench-{os.getpid()}")
    mkeys = iter(content_key(stage="radar_points", stage_version=1, config={"m": i}) for i in range(100))
    out["write_memory_uri_s"] = _median_s(lambda: mem.write("radar_points", next(mkeys), table), 3)
    print(
        f"radar_points {n_frames} frames x {n_points} points ({size_mb:.2f} MB zstd): "
        f"write {write_s * 1e3:.0f} ms ({out['write_frames_per_s']:.0f} frames/s), "
        f"read+decode {read_s * 1e3:.0f} ms ({out['read_frames_per_s']:.0f} frames/s); "
        f"memory:// write {out['write_memory_uri_s'] * 1e3:.0f} ms"
    )

    # -- demo scene through the plain runner ---------------------------------------------------
    scenes = [str(p) for p in demo_scene_paths()]
    plain = SimulateRequest(scenes=scenes, radar="ti-mmwcas", store=str(tmp / "demo-store"),
                            dataset="bench")
    skip_s = _median_s(lambda: [scene_keys(s, "ti-mmwcas") for s in scenes], 5)
    t0 = time.perf_counter()
    first = simulate_scenes(plain, PlainRunner())
    out["demo_plain_compute_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    second = simulate_scenes(plain, PlainRunner())
    out["demo_plain_cached_s"] = time.perf_counter() - t0
    out["scene_keys_s"] = skip_s
    n_pts = first["outcomes"][0]["measured"]["n_points"]
    out["demo_points_per_frame"] = n_pts
    assert second["counts"]["skipped"] == len(scenes)
    print(
        f"demo ({len(scenes)} scene, {len(n_pts)} frames, points/frame {n_pts}): plain loop "
        f"compute {out['demo_plain_compute_s']:.2f} s (incl. Mitsuba JIT), cached re-run "
        f"{out['demo_plain_cached_s'] * 1e3:.0f} ms, of which scene hashing + keys "
        f"{skip_s * 1e3:.0f} ms"
    )

    # -- the same through the Prefect flow -----------------------------------------------------
    from sim2radar.flows._states import run_flow
    from sim2radar.flows.simulate import simulate_dataset

    flowed = plain.model_copy(update={"store": str(tmp / "flow-store")})
    t0 = time.perf_counter()
    run_flow(simulate_dataset, request=flowed)
    out["demo_flow_first_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = run_flow(simulate_dataset, request=flowed)
    out["demo_flow_cached_s"] = time.perf_counter() - t0
    assert res["counts"]["skipped"] == len(scenes)
    print(
        f"Prefect flow: first run {out['demo_flow_first_s']:.1f} s (starts the ephemeral API + "
        f"computes), cached re-run {out['demo_flow_cached_s']:.2f} s (orchestration overhead)"
    )
    return out


if __name__ == "__main__":
    main()
