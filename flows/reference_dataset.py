"""Flow: the reference ("proxy-real") radar dataset — the signal-level reference radar on the
ground-truth geometry of procedural worlds disjoint from the simulated domain's, exported in
OpenPCDet's custom layout and labelled as a proxy for measured radar.

    from sim2radar.flows.reference_dataset import reference_dataset
    summary = reference_dataset(store="out/store", export_dir="data/proxy_real")  # 618 frames

It is the factory's generate-dataset flow (one task per world, one cached ``dataset_frames``
artifact per frame, failures recorded in the manifest while the others finish) run with the
reference radar preset (``fidelity: signal``), ``ground_truth`` geometry, no RGB rendering, the
plan of :func:`sim2radar.factory.reference.plan_reference` (worlds, frames, splits by world) and
an export whose ``dataset.json`` says ``domain: proxy-real (reference radar simulation)`` and
whose points carry Doppler as a 5th column.
"""

from __future__ import annotations

import importlib
import os
from typing import Any

from prefect import flow

from sim2radar.factory.reference import DOMAIN_LABEL, REFERENCE_FIRST_SEED, plan_reference
from sim2radar.worlds.config import WALKING_SPEED_MPS

__all__ = ["REFERENCE_RADAR", "reference_dataset", "reference_dataset_job", "reference_spec",
           "reference_run"]

#: The reference radar's preset.
REFERENCE_RADAR = "ti-mmwcas-reference"
#: The reference rig's walking speed range [m/s] (min, max; drawn per frame): a person
#: carrying the rig through a corridor, as every procedural-world dataset's.
REFERENCE_SPEED_MPS = WALKING_SPEED_MPS


def reference_spec(frames_per_world: int = 10, radar: Any = REFERENCE_RADAR, world: Any = None,
                   rig: Any = None, seed: int = 0, labels: Any = None,
                   speed_mps: tuple[float, float] = REFERENCE_SPEED_MPS):
    """The :class:`sim2radar.tasks.dataset.DatasetSpec` of a reference dataset: ground-truth geometry,
    the reference radar on a rig walking at ``speed_mps`` (min, max) [m/s] along its heading
    (a speed drawn per frame), no RGB / LiDAR rendering."""
    from sim2radar.factory.spec import DatasetSpec

    return DatasetSpec(frames_per_world=frames_per_world, geometry="ground_truth", radar=radar,
                       world=world, rig=rig, seed=seed, labels=labels, render_rgb=False,
                       motion={"speed_mps": list(speed_mps)})


def reference_run(first_seed: int = REFERENCE_FIRST_SEED, worlds: int | None = None,
                  frames_per_world: int = 10, seed: int = 0) -> dict[str, Any]:
    """The generate flow's arguments that make a reference dataset of this plan: ``seeds``,
    ``frames_by_seed``, ``splits`` (world ids), ``export_doppler``, ``domain``, plus ``plan``
    (:class:`~sim2radar.factory.reference.ReferencePlan`)."""
    from sim2radar.storage.worlds import world_id_for

    plan = plan_reference(first_seed, worlds=worlds, frames_per_world=frames_per_world,
                          seed=seed)
    return {"seeds": list(plan.seeds), "frames_by_seed": plan.frames_by_seed,
            "splits": {k: [world_id_for(s) for s in v] for k, v in plan.splits.items()},
            "export_doppler": True, "domain": DOMAIN_LABEL, "plan": plan}


def reference_dataset(
    store: str | os.PathLike = "out/store",
    dataset: str = "reference",
    export_dir: str | os.PathLike | None = None,
    *,
    first_seed: int = REFERENCE_FIRST_SEED,
    worlds: int | None = None,
    frames_per_world: int = 10,
    radar: Any = REFERENCE_RADAR,
    world: Any = None,
    rig: Any = None,
    seed: int = 0,
    labels: Any = None,
    speed_mps: tuple[float, float] = REFERENCE_SPEED_MPS,
    force: bool = False,
    strict: bool = False,
    workers: int = 1,
    dask_address: str | None = None,
) -> dict[str, Any]:
    """Build (or find cached) a reference dataset; returns the generate flow's summary plus
    ``plan`` (frames per split).

    Parameters
    ----------
    worlds : number of worlds of ``frames_per_world`` frames (None: sized like the paper's
        371 / 92 / 155 split, :func:`~sim2radar.factory.reference.plan_reference`).
    first_seed : seed of the first world (keep it disjoint from the simulated domain's worlds).
    speed_mps : the rig's walking speed range [m/s] (min, max; drawn per frame).
    Other parameters as :func:`sim2radar.flows.generate_dataset.generate_dataset`.
    """
    from sim2radar.flows._states import run_flow
    from sim2radar.flows.generate_dataset import generate_dataset_flow
    from sim2radar.flows.runners import task_runner

    args = reference_run(first_seed, worlds, frames_per_world, seed)
    plan = args.pop("plan")
    spec = reference_spec(frames_per_world, radar, world, rig, seed, labels, speed_mps)
    runner = task_runner(workers, dask_address)
    summary = run_flow(
        generate_dataset_flow.with_options(task_runner=runner, name="reference-dataset"),
        spec=spec.to_dict(), store=os.fspath(store), dataset=dataset,
        export_dir=None if export_dir is None else os.fspath(export_dir), force=force,
        strict=strict, **args,
    )
    summary["plan"] = plan.split_frames()
    return summary


@flow(name="reference-dataset-job", log_prints=False)
def reference_dataset_job(
    store: str = "out/store",
    dataset: str = "reference",
    export_dir: str | None = None,
    first_seed: int = REFERENCE_FIRST_SEED,
    worlds: int | None = None,
    frames_per_world: int = 10,
    radar: str | dict = REFERENCE_RADAR,
    seed: int = 0,
    speed_mps: tuple[float, float] = REFERENCE_SPEED_MPS,
    force: bool = False,
    strict: bool = False,
    workers: int = 1,
    dask_address: str | None = None,
) -> dict[str, Any]:
    """Deployment entry point (``deploy/prefect.yaml``): :func:`reference_dataset` as a
    subflow (the package's copy, so Dask workers can import it)."""
    from sim2radar.flows._states import relay

    package = importlib.import_module("sim2radar.flows.reference_dataset")
    return relay(package.reference_dataset(
        store=store, dataset=dataset, export_dir=export_dir, first_seed=first_seed,
        worlds=worlds, frames_per_world=frames_per_world, radar=radar, seed=seed,
        speed_mps=tuple(speed_mps), force=force,
        strict=strict, workers=workers, dask_address=dask_address), "worlds")
