"""Flow: reconstruct RGB [+ LiDAR] frames into material-labelled scenes in the artifact store.

    from sim2radar.flows.reconstruct import run_reconstruction
    summary = run_reconstruction(["img/0001.png", ...], intrinsics="K.yaml",
                                 lidar=["lidar/0001.npy", ...], store="out/store",
                                 dataset="my-building", config=ReconstructionConfig())

One task per frame, gathered as they complete; each outcome goes into the dataset manifest. A
second run with the same inputs recomputes nothing (every frame ``skipped`` by content key); a
failing frame is recorded as ``failed`` with its error and the others finish.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from prefect import flow, get_run_logger
from prefect.futures import as_completed
from sim2radar.storage import ArtifactStore
from sim2radar.tasks.reconstruct import (
    ImageJob,
    ReconOutcome,
    failed_outcome,
    reconstruct_image_task,
    record_recon_outcome_task,
    summarize_recon,
)
from sim2radar.tasks.runners import ThreadRunner

__all__ = ["reconstruct_flow", "run_reconstruction"]


@flow(name="reconstruct-frames", task_runner=ThreadRunner(max_workers=1), log_prints=False)
def reconstruct_flow(
    jobs: list[ImageJob],
    store: str = "out/store",
    dataset: str = "reconstruction",
    config: dict | None = None,
    out_dir: str | None = None,
    force: bool = False,
) -> dict[str, Any]:
    """Reconstruct each frame and record it in the ``dataset`` manifest.

    Returns
    -------
    dict — ``{"store", "dataset", "counts": {ok, skipped, failed}, "frames": [...]}``
    """
    logger = get_run_logger()
    ArtifactStore(store).manifest(dataset)
    futures = {
        reconstruct_image_task.with_options(task_run_name=f"reconstruct-{job.name}").submit(
            job, store, config, out_dir, force): i
        for i, job in enumerate(jobs)
    }
    outcomes: dict[int, ReconOutcome] = {}
    for fut in as_completed(list(futures)):
        i = futures[fut]
        result = fut.result(raise_on_failure=False)
        if isinstance(result, ReconOutcome):
            outcome = result
        else:
            error = result if isinstance(result, BaseException) else (
                fut.state.message or repr(result))
            outcome = failed_outcome(jobs[i], error)
        record_recon_outcome_task(store, dataset, outcome)
        logger.info("frame %s: %s %s", outcome.name, outcome.status, outcome.error)
        outcomes[i] = outcome
    summary = summarize_recon([outcomes[i] for i in range(len(jobs))], store, dataset)
    logger.info("reconstruct-frames: %s into %s (dataset %s)", summary["counts"], store, dataset)
    return summary


def run_reconstruction(
    images: Sequence[str | os.PathLike],
    intrinsics: str | os.PathLike,
    lidar: Sequence[str | os.PathLike] | None = None,
    store: str | os.PathLike = "out/store",
    dataset: str = "reconstruction",
    config=None,
    *,
    out_dir: str | os.PathLike | None = None,
    force: bool = False,
    workers: int = 1,
) -> dict[str, Any]:
    """Run :func:`reconstruct_flow`; ``config`` may be a ReconstructionConfig or a dict."""
    lidar = list(lidar or [])
    if lidar and len(lidar) != len(images):
        raise ValueError(f"got {len(lidar)} LiDAR files for {len(images)} images; give one each")
    jobs = [ImageJob(os.fspath(img), os.fspath(intrinsics), os.fspath(lidar[i]) if lidar else None)
            for i, img in enumerate(images)]
    cfg = config.to_dict() if hasattr(config, "to_dict") else (config or None)
    runner = ThreadRunner(max_workers=max(1, int(workers)))
    return reconstruct_flow.with_options(task_runner=runner)(
        jobs=jobs, store=os.fspath(store), dataset=dataset, config=cfg,
        out_dir=os.fspath(out_dir) if out_dir else None, force=force)
