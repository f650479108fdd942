"""Flow: generate N procedural worlds x M rendered frames into the artifact store.

    from sim2radar.flows.worlds import generate_worlds_flow
    from sim2radar.tasks.worlds import WorldsRequest
    summary = generate_worlds_flow(WorldsRequest(seeds=[0, 1, 2, 3], n_frames=8,
                                                 store="out/store", dataset="worlds"))

The job's driver is :func:`sim2radar.tasks.worlds.generate_worlds`; this flow runs it with
:class:`~sim2radar.flows.engine.PrefectRunner`: one ``generate-world`` task per seed, gathered
as they complete. A second run with the same inputs recomputes nothing (every world
``skipped`` by content key). A failing world is recorded as ``failed``, the others finish and
the run ends Failed carrying its summary.
"""

from __future__ import annotations

from typing import Any

from prefect import flow

from sim2radar.flows._states import finish_run
from sim2radar.flows.engine import PrefectRunner
from sim2radar.tasks.worlds import WorldsRequest, generate_worlds

__all__ = ["generate_worlds_flow", "WorldsRequest"]


@flow(name="generate-worlds", log_prints=False)
def generate_worlds_flow(request: WorldsRequest) -> dict[str, Any]:
    """Generate, render and store each world of ``request``
    (:func:`sim2radar.tasks.worlds.generate_worlds`)."""
    return finish_run(generate_worlds(request, PrefectRunner(request.run)), "worlds")
