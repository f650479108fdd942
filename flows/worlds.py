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

from prefect import flow, get_run_logger
from prefect.futures import as_completed
from sim2radar.storage import ArtifactStore
from sim2radar.tasks.runners import ThreadRunner
from sim2radar.tasks.worlds import (
    WorldOutcome,
    failed_world,
    generate_world_task,
    record_world_outcome_task,
    summarize_worlds,
)

__all__ = ["worlds_flow", "run_worlds"]


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
    dict — ``{"store", "dataset", "counts": {ok, skipped, failed}, "worlds": [...]}``
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
    outcomes: dict[int, WorldOutcome] = {}
    for fut in as_completed(list(futures)):
        seed = futures[fut]
        result = fut.result(raise_on_failure=False)
        if isinstance(result, WorldOutcome):
            outcome = result
        else:
            error = result if isinstance(result, BaseException) else (
                fut.state.message or repr(result))
            outcome = failed_world(seed, error)
        record_world_outcome_task(store, dataset, outcome)
        logger.info("world %s: %s %s", outcome.world_id, outcome.status, outcome.error)
        outcomes[seed] = outcome
    summary = summarize_worlds(st, dataset, [outcomes[int(s)] for s in seeds])
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
