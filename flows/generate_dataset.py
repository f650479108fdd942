"""Flow: the factory's nightly job — N procedural worlds x M frames -> radar frames with door
boxes (on reconstructed and/or ground-truth geometry) in the store, optionally exported to
OpenPCDet's custom layout.

    from sim2radar.flows.generate_dataset import generate_dataset
    from sim2radar.tasks.generate import GenerateRequest
    spec = DatasetSpec(frames_per_world=8, geometry="both")   # + radar, reconstruction, ...
    summary = generate_dataset(GenerateRequest(spec=spec, seeds=[0, 1, 2, 3],
                                               store="out/store", dataset="nightly",
                                               export_dir="out/openpcdet"))

The job's driver is :func:`sim2radar.tasks.generate.generate_dataset`; this flow runs it with
:class:`~sim2radar.flows.engine.PrefectRunner`: one ``generate-world-dataset`` task per world
seed, its steps (render, reconstruction steps per frame, one simulate per geometry) as nested
tasks that end **Cached** when their artifact exists; worlds are gathered as they complete;
each world's outcome (world row + one row per frame) goes into the dataset manifest; a table
artifact lists seconds per step. A second run with the same inputs recomputes nothing (every
frame ``skipped`` by content key). A failing world or frame is recorded as ``failed`` with its
error, the others finish and the run ends Failed carrying its summary; ``strict=True`` raises
:class:`~sim2radar.tasks.generate.DatasetFailures` (after everything is recorded and exported).
It is also the ``nightly-generate`` deployment's entrypoint.

Task runner (``request.run``, :func:`sim2radar.flows.runners.task_runner`): worlds run one at
a time by default (Mitsuba already uses every core for one frame); ``workers > 1`` uses a
thread pool; ``dask_address`` = a Dask scheduler address (``tcp://host:8786``) or ``"local"``
(a LocalCluster of ``workers`` single-threaded processes) fans worlds out over Dask
(``pip install 'sim2radar[dask]'``). A world task receives only its seed and the request (the
spec, the store path/URI); the frames it makes go to the store and only a small outcome comes
back, so everything pickles and each worker process selects its own Mitsuba variant.
"""

from __future__ import annotations

from typing import Any

from prefect import flow

from sim2radar.flows._states import finish_run
from sim2radar.flows.engine import PrefectRunner
from sim2radar.tasks.generate import DatasetFailures, GenerateRequest
from sim2radar.tasks.generate import generate_dataset as _driver

__all__ = ["generate_dataset", "GenerateRequest", "DatasetFailures"]


@flow(name="generate-dataset", log_prints=False)
def generate_dataset(request: GenerateRequest) -> dict[str, Any]:
    """Generate each world's dataset frames and record them in the dataset manifest
    (:func:`sim2radar.tasks.generate.generate_dataset`); ends Failed when a world failed."""
    summary = _driver(request, PrefectRunner(request.run))
    fc = summary["frame_counts"]
    return finish_run(summary, "worlds", detail=f" ({fc['failed']} of {sum(fc.values())} frames)")
