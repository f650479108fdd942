"""Flow: the reference ("proxy-real") radar dataset (:mod:`sim2radar.tasks.reference`): the
``generate`` job with the reference radar on ground-truth geometry of worlds disjoint from
the simulated domain's, run with :class:`~sim2radar.flows.engine.PrefectRunner`.

    from sim2radar.flows.reference_dataset import reference_dataset
    from sim2radar.tasks.reference import ReferenceRequest
    summary = reference_dataset(ReferenceRequest(store="out/store",
                                                 export_dir="data/proxy_real"))  # 618 frames

It is also the ``weekly-reference`` deployment's entrypoint.
"""

from __future__ import annotations

from typing import Any

from prefect import flow

from sim2radar.flows._states import finish_run
from sim2radar.flows.engine import PrefectRunner
from sim2radar.tasks.reference import ReferenceRequest
from sim2radar.tasks.reference import reference_dataset as _driver

__all__ = ["reference_dataset", "ReferenceRequest"]


@flow(name="reference-dataset", log_prints=False)
def reference_dataset(request: ReferenceRequest) -> dict[str, Any]:
    """Build (or find cached) the reference dataset of ``request``
    (:func:`sim2radar.tasks.reference.reference_dataset`); ends Failed when a world failed."""
    return finish_run(_driver(request, PrefectRunner(request.run)), "worlds")
