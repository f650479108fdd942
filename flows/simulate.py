"""Flow: simulate radar point clouds for scene files into the artifact store.

    from sim2radar.flows.simulate import run_simulation
    summary = run_simulation(["scene.yaml"], radar="ti-mmwcas", store="out/store", dataset="demo")

One task per scene (``simulate_scene_task.submit``), gathered as they complete; each outcome
is written to the dataset manifest (``store.manifest(dataset)``). A second run with the same
inputs recomputes nothing: every scene is ``skipped`` by content key.

Failure policy: a broken scene (bad mesh file, unknown material, ...) fails its own task; the
flow records it as ``failed`` (with the error text) in the manifest and lets the other scenes
finish. The flow then *returns* its summary (``counts["failed"] > 0``) — a dataset run is a
batch job that should keep what succeeded — unless ``strict=True``, which raises
:class:`SceneFailures` after every scene has been recorded (Prefect marks the run failed). The
CLI maps this to its exit code: 0 by default, 1 with ``--strict`` when any scene failed.

Task runner (:func:`sim2radar.flows.runners.task_runner`): scenes run one at a time by default
(``workers=1``: Mitsuba/Dr.Jit already uses every core for one frame). ``workers>1`` uses a
thread pool; ``dask_address`` = a scheduler address (``tcp://host:8786``) or ``"local"`` (a
LocalCluster of ``workers`` processes) uses ``prefect_dask.DaskTaskRunner`` (``pip install
'sim2radar[dask]'``). Tasks receive paths/URIs and plain values only, so they pickle.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from prefect import flow, get_run_logger

from sim2radar.configio import DEFAULT_RADAR
from sim2radar.flows import _progress
from sim2radar.flows._states import finish, relay, run_flow
from sim2radar.flows._steps import gather
from sim2radar.flows.runners import ThreadRunner, task_runner
from sim2radar.scenes import expand_scenes
from sim2radar.storage import ArtifactStore
from sim2radar.tasks.common import Outcome, summarize
from sim2radar.tasks.radar import failed_outcome, simulate_scene_task

__all__ = [
    "simulate_flow",
    "simulate_dataset",
    "run_simulation",
    "expand_scenes",
    "SceneFailures",
    "progress_callback",
]


class SceneFailures(RuntimeError):
    """Raised by a ``strict`` run when at least one scene failed; ``.summary`` has the details."""

    def __init__(self, summary: dict[str, Any]) -> None:
        failed = [s for s in summary["outcomes"] if s["status"] == "failed"]
        lines = [f"{s['id']}: {s['error']}" for s in failed]
        super().__init__(f"{len(failed)} scene(s) failed:\n" + "\n".join(lines))
        self.summary = summary


def progress_callback(fn: Callable[[Outcome], None]):
    """Context manager: call ``fn(outcome)`` in this process after each scene finishes."""
    return _progress.listen("simulate", fn)


def _check_unique_ids(scenes: Sequence[str]) -> None:
    from sim2radar.scenes import scene_id_for

    seen: dict[str, str] = {}
    for s in scenes:
        sid = scene_id_for(s)
        if sid in seen and os.path.abspath(seen[sid]) != os.path.abspath(s):
            raise ValueError(
                f"two scene files share the scene id {sid!r}: {seen[sid]} and {s}; give each a "
                "unique 'name:' in its YAML or write them to different datasets"
            )
        seen[sid] = s


@flow(name="simulate-radar", task_runner=ThreadRunner(max_workers=1), log_prints=False)
def simulate_flow(
    scenes: list[str],
    radar: str = DEFAULT_RADAR,
    store: str = "out/store",
    dataset: str = "default",
    seed: int = 0,
    png_dir: str | None = None,
    force: bool = False,
    strict: bool = False,
) -> dict[str, Any]:
    """Simulate each scene file into ``store`` and record it in the ``dataset`` manifest.

    Parameters
    ----------
    scenes : scene YAML paths (:mod:`sim2radar.scenes`)
    radar : radar preset name or YAML path
    store : artifact store root (local path or fsspec URI)
    dataset : manifest name
    seed : run seed
    png_dir : folder for bird's-eye-view PNGs (local), or None
    force : recompute even when artifacts exist
    strict : raise :class:`SceneFailures` at the end if any scene failed

    Returns
    -------
    dict
        :func:`sim2radar.tasks.common.summarize`'s (``outcomes``: the scenes) + ``radar``
    """
    logger = get_run_logger()
    scenes = [str(s) for s in scenes]
    _check_unique_ids(scenes)
    st = ArtifactStore(store)
    st.manifest(dataset)  # validates the dataset name before any work
    futures = {
        simulate_scene_task.with_options(task_run_name=f"simulate-{Path(s).stem}").submit(
            s, radar, store, seed=seed, png_dir=png_dir, force=force
        ): s
        for s in scenes
    }
    done = gather(futures, failed_outcome, store=store, dataset=dataset, channel="simulate",
                  what="scene")
    summary = summarize(st, dataset, [done[s] for s in scenes], radar=str(radar))
    counts = summary["counts"]
    logger.info("simulate-radar: %s into %s (dataset %s)", counts, st.root, dataset)
    if strict and counts["failed"]:
        raise SceneFailures(summary)
    return finish(summary, failed=counts["failed"], total=len(scenes), unit="scenes")


def run_simulation(
    scenes: Sequence[str | os.PathLike],
    radar: str = DEFAULT_RADAR,
    store: str | os.PathLike = "out/store",
    dataset: str = "default",
    *,
    seed: int = 0,
    png_dir: str | os.PathLike | None = None,
    force: bool = False,
    strict: bool = False,
    workers: int = 1,
    dask_address: str | None = None,
) -> dict[str, Any]:
    """Run :func:`simulate_flow` with a chosen task runner (see the module docstring)."""
    runner = task_runner(workers, dask_address)
    return run_flow(
        simulate_flow.with_options(task_runner=runner),
        scenes=[str(s) for s in scenes],
        radar=str(radar),
        store=os.fspath(store),
        dataset=dataset,
        seed=seed,
        png_dir=None if png_dir is None else os.fspath(png_dir),
        force=force,
        strict=strict,
    )


@flow(name="simulate-dataset", log_prints=False)
def simulate_dataset(
    scenes: list[str],
    radar: str = DEFAULT_RADAR,
    store: str = "out/store",
    dataset: str = "default",
    seed: int = 0,
    png_dir: str | None = None,
    strict: bool = False,
    workers: int = 1,
    dask_address: str | None = None,
) -> dict[str, Any]:
    """Deployment entry point (see ``deploy/prefect.yaml``): expand scene files / folders /
    globs and run :func:`simulate_flow` as a subflow on the chosen task runner (threads, or
    Dask with ``dask_address`` = scheduler address or ``"local"``)."""
    # Prefect loads a deployment's entrypoint file as a top-level module ("simulate"); objects
    # from that copy would pickle by reference to a module Dask's scheduler and workers cannot
    # import. Run the package's copy of the flow instead (the same code).
    package = importlib.import_module("sim2radar.flows.simulate")
    return relay(package.run_simulation(
        expand_scenes(scenes),
        radar=radar,
        store=store,
        dataset=dataset,
        seed=seed,
        png_dir=png_dir,
        strict=strict,
        workers=workers,
        dask_address=dask_address,
    ), "scenes")
