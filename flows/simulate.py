"""Flow: simulate radar point clouds for scene files into the artifact store.

    from sim2radar.flows.simulate import simulate_dataset
    from sim2radar.tasks.radar import SimulateRequest
    summary = simulate_dataset(SimulateRequest(scenes=["scene.yaml"], radar="ti-mmwcas",
                                               store="out/store", dataset="demo"))

The job's driver is :func:`sim2radar.tasks.radar.simulate_scenes`; this flow runs it with
:class:`~sim2radar.flows.engine.PrefectRunner`: one ``simulate-scene`` task per scene, gathered
as they complete, each outcome written to the dataset manifest. It is also the deployment
entrypoint (``nightly-radar``, ``radar-on-demand``: ``sim2radar deploy``).

Failure policy: a broken scene (bad mesh file, unknown material, ...) fails its own task; the
flow records it as ``failed`` (with the error text) in the manifest and lets the other scenes
finish, then ends **Failed** carrying its summary (:mod:`sim2radar.flows._states`);
``strict=True`` raises :class:`~sim2radar.tasks.radar.SceneFailures` instead.

Task runner (``request.run``, :func:`sim2radar.flows.runners.task_runner`): scenes run one at a
time by default (``workers=1``: Mitsuba/Dr.Jit already uses every core for one frame).
``workers>1`` uses a thread pool; ``dask_address`` = a scheduler address (``tcp://host:8786``)
or ``"local"`` (a LocalCluster of ``workers`` processes) uses ``prefect_dask.DaskTaskRunner``
(``pip install 'sim2radar[dask]'``). Tasks receive paths/URIs and plain values only, so they
pickle.
"""

from __future__ import annotations

from typing import Any

from prefect import flow

from sim2radar.flows._states import finish_run
from sim2radar.flows.engine import PrefectRunner
from sim2radar.tasks.radar import SceneFailures, SimulateRequest, simulate_scenes

__all__ = ["simulate_dataset", "SimulateRequest", "SceneFailures"]


@flow(name="simulate-dataset", log_prints=False)
def simulate_dataset(request: SimulateRequest) -> dict[str, Any]:
    """Simulate each scene of ``request`` into its store and record it in the dataset manifest
    (:func:`sim2radar.tasks.radar.simulate_scenes`); ends Failed when a scene failed."""
    return finish_run(simulate_scenes(request, PrefectRunner(request.run)), "scenes")
