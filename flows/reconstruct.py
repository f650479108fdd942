"""Flow: reconstruct RGB [+ LiDAR] frames into material-labelled scenes in the artifact store.

    from sim2radar.flows.reconstruct import reconstruct_frames
    from sim2radar.tasks.reconstruct import ImageJob, ReconstructRequest
    summary = reconstruct_frames(ReconstructRequest(
        jobs=[ImageJob("img/0001.png", "K.yaml", "lidar/0001.npy")], store="out/store",
        dataset="my-building"))

The job's driver is :func:`sim2radar.tasks.reconstruct.reconstruct_images`; this flow runs it
with :class:`~sim2radar.flows.engine.PrefectRunner`: one ``reconstruct-image`` task per frame,
gathered as they complete, each outcome in the dataset manifest. A second run with the same
inputs recomputes nothing (every frame ``skipped`` by content key); a failing frame is recorded
as ``failed`` with its error, the others finish and the run ends Failed carrying its summary.
"""

from __future__ import annotations

from typing import Any

from prefect import flow

from sim2radar.flows._states import finish_run
from sim2radar.flows.engine import PrefectRunner
from sim2radar.tasks.reconstruct import ReconstructRequest, reconstruct_images

__all__ = ["reconstruct_frames", "ReconstructRequest"]


@flow(name="reconstruct-frames", log_prints=False)
def reconstruct_frames(request: ReconstructRequest) -> dict[str, Any]:
    """Reconstruct each frame of ``request`` and record it in the dataset manifest
    (:func:`sim2radar.tasks.reconstruct.reconstruct_images`)."""
    return finish_run(reconstruct_images(request, PrefectRunner(request.run)), "frames")
