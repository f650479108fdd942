"""Flow: generate N procedural worlds x M rendered frames into the artifact store.

    from sim2radar.flows.worlds import run_worlds
    summary = run_worlds(range(4), n_frames=8, store="out/store", dataset="worlds")

One task per world seed, gathered as they complete; each outcome goes into the dataset
manifest. A second run with the same inputs recomputes nothing (every world ``skipped`` by
content key). A failing world is recorded as ``failed`` and the others finish.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from typing import Any

from prefect import flow, get_run_logger, task
from prefect.cache_policies import NO_CACHE

from sim2radar.flows._steps import gather
from sim2radar.flows.runners import ThreadRunner
from sim2radar.storage import ArtifactStore
from sim2radar.tasks.common import Outcome, summarize
from sim2radar.tasks.worlds import failed_world, generate_world_artifacts

__all__ = ["worlds_flow", "run_worlds", "generate_world_task"]


@task(name="generate-world", cache_policy=NO_CACHE, retries=0, persist_result=False)
def generate_world_task(seed: int, n_frames: int, store: str, world_cfg: dict, rig: dict,
                        trajectory_seed: int = 0, force: bool = False,
                        radar: str | None = None) -> Outcome:
    """One world (:func:`sim2radar.tasks.worlds.generate_world_artifacts`); rendering is
    deterministic, so no retries; caching is by content key inside it."""
    return generate_world_artifacts(seed, n_frames, store, world_cfg, rig,
                                    trajectory_seed=trajectory_seed, force=force, radar=radar)


@flow(name="generate-worlds", task_runner=ThreadRunner(max_workers=1), log_prints=False)
def worlds_flow(
    seeds: list[int],
    n_frames: int = 4,
    store: str = "out/store",
    dataset: str = "worlds",
    world_cfg: dict | None = None,
    rig: dict | None = None,
    trajectory_seed: int = 0,
    force: bool = False,
    radar: str | None = None,
) -> dict[str, Any]:
    """Generate, render and store each world; record it in the ``dataset`` manifest
    (``radar``: also simulate radar point clouds per frame with that preset / YAML).

    Returns
    -------
    dict — :func:`sim2radar.tasks.common.summarize`'s (``outcomes``: the worlds)
    """
    logger = get_run_logger()
    st = ArtifactStore(store)
    st.manifest(dataset)
    futures = {
        generate_world_task.with_options(task_run_name=f"world-{s}").submit(
            int(s), n_frames, store, world_cfg or {}, rig or {}, trajectory_seed, force,
            radar): int(s)
        for s in seeds
    }
    done = gather(futures, failed_world, store=store, dataset=dataset, what="world")
    summary = summarize(st, dataset, [done[int(s)] for s in seeds])
    logger.info("generate-worlds: %s into %s (dataset %s)", summary["counts"], st.root, dataset)
    return summary


def run_worlds(
    seeds: Iterable[int],
    n_frames: int = 4,
    store: str | os.PathLike = "out/store",
    dataset: str = "worlds",
    world_cfg=None,
    rig=None,
    *,
    trajectory_seed: int = 0,
    force: bool = False,
    workers: int = 1,
    radar: str | None = None,
) -> dict[str, Any]:
    """Run :func:`worlds_flow`; configs may be pydantic models or dicts."""

    def dump(cfg):
        return cfg.model_dump(mode="json") if hasattr(cfg, "model_dump") else (cfg or {})

    runner = ThreadRunner(max_workers=max(1, int(workers)))
    return worlds_flow.with_options(task_runner=runner)(
        seeds=[int(s) for s in seeds], n_frames=int(n_frames), store=os.fspath(store),
        dataset=dataset, world_cfg=dump(world_cfg), rig=dump(rig),
        trajectory_seed=int(trajectory_seed), force=force,
        radar=None if radar is None else str(radar),
    )
