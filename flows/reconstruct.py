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

from sim2radar.flows._steps import gather
from sim2radar.flows.runners import ThreadRunner
from sim2radar.storage import ArtifactStore
from sim2radar.tasks.common import summarize
from sim2radar.tasks.reconstruct import ImageJob, failed_outcome, reconstruct_image_task

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
    dict — :func:`sim2radar.tasks.common.summarize`'s
    """
    logger = get_run_logger()
    ArtifactStore(store).manifest(dataset)
    futures = {
        reconstruct_image_task.with_options(task_run_name=f"reconstruct-{job.name}").submit(
            job, store, config, out_dir, force): i
        for i, job in enumerate(jobs)
    }
    done = gather(futures, lambda i, error: failed_outcome(jobs[i], error), store=store,
                  dataset=dataset, what="frame")
    summary = summarize(store, dataset, [done[i] for i in range(len(jobs))])
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
