"""Scale-out benchmark: the generate-dataset flow on N small worlds with the thread runner
(``workers=1``) vs a Dask ``LocalCluster`` of 2 single-threaded worker processes.

Three runs, each into a fresh store (nothing cached), all through the Prefect flow
(:func:`sim2radar.flows.generate_dataset.generate_dataset` with a
:class:`~sim2radar.tasks.generate.GenerateRequest` whose ``run`` picks the task runner) on one
temporary Prefect API:

* ``threads``      — ``ThreadPoolTaskRunner(1)``: worlds one after another in this process
  (Mitsuba/Dr.Jit still uses every core inside a frame), after a warm-up run on other worlds
  (imports, Mitsuba variant, JIT kernels) so that it is compared warm with warm;
* ``dask_cold``    — ``dask_address="local"``: the runner starts a 2-process LocalCluster for
  the run (process start, imports, Mitsuba variant and JIT warm-up included);
* ``dask_warm``    — the same cluster kind started beforehand and warmed up on one world in a
  scratch store, then given by address (steady state of a long-running cluster).

Speed-up = threads wall / Dask wall. On a 2-core machine expect at most ~2x, and less: one
Mitsuba frame already spreads over both cores, so two processes mainly overlap the
single-threaded parts (world generation, reconstruction, Parquet I/O, Prefect bookkeeping).

    python -m benchmarks scaleout
    SIM2RADAR_BENCH_SCALEOUT_WORLDS=8 python -m benchmarks scaleout
"""

from __future__ import annotations

import os
import tempfile
import time

N_WORLDS = int(os.environ.get("SIM2RADAR_BENCH_SCALEOUT_WORLDS", "4"))
FRAMES = int(os.environ.get("SIM2RADAR_BENCH_SCALEOUT_FRAMES", "2"))
DASK_WORKERS = 2
RIG = {"width": 160, "height": 120, "spp": 4}
WORLD = {"corridor_length_m": [10, 14]}
GEOMETRY = "both"


def _run(store: str, *, first_seed: int = 0, n_worlds: int = N_WORLDS, **run) -> tuple:
    """One run of the ``generate-dataset`` flow on worlds ``first_seed ..``; ``run`` holds
    :class:`~sim2radar.tasks.runner.RunOptions` fields (``workers``, ``dask_address``)."""
    from sim2radar.flows._states import run_flow
    from sim2radar.flows.generate_dataset import GenerateRequest, generate_dataset

    t0 = time.perf_counter()
    spec = {"frames_per_world": FRAMES, "geometry": GEOMETRY, "world": WORLD, "rig": RIG}
    request = GenerateRequest(spec=spec, n_worlds=n_worlds, first_seed=first_seed, store=store,
                              dataset="bench", run=run)
    summary = run_flow(generate_dataset, request=request)
    wall_s = time.perf_counter() - t0
    if summary["counts"]["failed"]:
        raise RuntimeError(f"benchmark run failed: {summary['counts']}")
    return wall_s, summary


def main() -> dict:
    import distributed
    from prefect.testing.utilities import prefect_test_harness

    from sim2radar.flows.runners import local_cluster_kwargs

    n_frames = N_WORLDS * FRAMES
    print(f"{N_WORLDS} worlds x {FRAMES} frames ({n_frames} frames), rig {RIG['width']}x"
          f"{RIG['height']} spp {RIG['spp']}, geometry {GEOMETRY}, {os.cpu_count()} CPU cores")
    out: dict = {"worlds": N_WORLDS, "frames_per_world": FRAMES, "cpu_cores": os.cpu_count()}
    with tempfile.TemporaryDirectory(prefix="bench-scaleout-") as tmp, \
            prefect_test_harness(server_startup_timeout=120):
        _run(os.path.join(tmp, "warmup-threads"), first_seed=1000, n_worlds=1)
        out["threads_s"], _ = _run(os.path.join(tmp, "threads"), workers=1)
        out["dask_cold_s"], _ = _run(os.path.join(tmp, "cold"), workers=DASK_WORKERS,
                                     dask_address="local")
        with distributed.LocalCluster(**local_cluster_kwargs(DASK_WORKERS)) as cluster:
            # warm both processes (imports, Mitsuba variant, JIT) on other worlds
            _run(os.path.join(tmp, "warmup"), first_seed=1000, n_worlds=DASK_WORKERS,
                 dask_address=cluster.scheduler_address)
            out["dask_warm_s"], _ = _run(os.path.join(tmp, "warm"),
                                         dask_address=cluster.scheduler_address)
    print("runner                         wall s    s/frame   speed-up vs threads")
    for name, key in (("threads (workers=1)", "threads_s"),
                      (f"Dask local, {DASK_WORKERS} procs, cold", "dask_cold_s"),
                      (f"Dask local, {DASK_WORKERS} procs, warm", "dask_warm_s")):
        wall = out[key]
        print(f"{name:30s} {wall:7.1f}   {wall / n_frames:7.2f}   "
              f"{out['threads_s'] / wall:5.2f}x")
    out["speedup_cold"] = out["threads_s"] / out["dask_cold_s"]
    out["speedup_warm"] = out["threads_s"] / out["dask_warm_s"]
    print(f"(a {os.cpu_count()}-core machine: at most ~{os.cpu_count()}x; Mitsuba already "
          "uses every core inside one frame)")
    return out


if __name__ == "__main__":
    main()
