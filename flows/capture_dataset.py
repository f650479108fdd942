"""Flow: a lab's RGB capture folder -> a radar dataset, one scene at a time, stage by stage.

    from sim2radar.flows.capture_dataset import capture_dataset
    from sim2radar.tasks.capture import CaptureRequest
    summary = capture_dataset(CaptureRequest(captures="captures/", store="out/store",
                                             dataset="lab", export_dir="out/openpcdet"))

The job's driver is :func:`sim2radar.tasks.capture.capture_dataset`; this flow runs it with
:class:`~sim2radar.flows.engine.PrefectRunner`: per scene (one RGB view) a ``capture-scene``
task runs :func:`sim2radar.tasks.capture.process_capture_scene` with every step as its own
Prefect task (``depth``, ``segments``, ``materials``, ``scene``, ``poses``, ``simulate`` per
batch of ``frames_per_task`` radar poses), so the UI shows per scene which stage ran, was
**Cached** (its artifact existed), was retried or failed, and how long it took. Only
``materials`` is retried (backoff 2 s, 8 s) and only on network errors (the VLM server);
deterministic and local-I/O failures fail at once. Manifest writes are retried (remote
stores). The run publishes a progress artifact that moves as scenes finish and a table
artifact (scenes ok/failed/skipped, frames, points per frame, seconds per stage). It is also
the ``captures-on-demand`` deployment's entrypoint.

A failing scene is recorded ``failed`` with its stage and error, the others finish and the run
ends Failed carrying its summary; a second run recomputes nothing. Scenes run one at a time by
default (Mitsuba uses every core); ``workers > 1`` uses threads, ``dask_address`` a Dask
cluster (:func:`sim2radar.flows.runners.task_runner`).
"""

from __future__ import annotations

from typing import Any

from prefect import flow

from sim2radar.flows._states import finish_run
from sim2radar.flows.engine import PrefectRunner
from sim2radar.tasks.capture import CaptureRequest
from sim2radar.tasks.capture import capture_dataset as _driver

__all__ = ["capture_dataset", "CaptureRequest"]


@flow(name="capture-dataset", log_prints=False)
def capture_dataset(request: CaptureRequest) -> dict[str, Any]:
    """Every capture scene of ``request`` through its steps into the store, the dataset
    manifest and the export (:func:`sim2radar.tasks.capture.capture_dataset`)."""
    return finish_run(_driver(request, PrefectRunner(request.run)), "scenes")
