"""The ``reference`` job: the reference ("proxy-real") radar dataset — the signal-level
reference radar on the ground-truth geometry of procedural worlds disjoint from the simulated
domain's, exported in OpenPCDet's custom layout and labelled as a proxy for measured radar.

    from sim2radar.tasks.reference import ReferenceRequest, reference_dataset
    from sim2radar.tasks.runner import PlainRunner
    summary = reference_dataset(ReferenceRequest(export_dir="data/proxy_real"), PlainRunner())

It is the ``generate`` job (:func:`sim2radar.tasks.generate.generate_dataset`: one unit per
world, one cached ``dataset_frames`` artifact per frame, failures recorded in the manifest
while the others finish) with the reference radar preset (``fidelity: signal``),
``ground_truth`` geometry, no RGB rendering, the plan of
:func:`sim2radar.factory.reference.plan_reference` (worlds, frames, splits by world) and an
export whose ``dataset.json`` says ``domain: proxy-real (reference radar simulation)`` and
whose points carry Doppler as a 5th column. The flow :mod:`sim2radar.flows.reference_dataset`
runs it with Prefect.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from sim2radar.factory.reference import DOMAIN_LABEL, REFERENCE_FIRST_SEED, plan_reference
from sim2radar.factory.spec import DatasetSpec
from sim2radar.tasks.common import RunSummary
from sim2radar.tasks.generate import GenerateRequest, generate_dataset
from sim2radar.tasks.runner import Runner, RunOptions
from sim2radar.worlds.config import WALKING_SPEED_MPS

__all__ = ["REFERENCE_RADAR", "REFERENCE_SPEED_MPS", "ReferenceRequest", "reference_spec",
           "reference_dataset"]

#: The reference radar's preset.
REFERENCE_RADAR = "ti-mmwcas-reference"
#: The reference rig's walking speed range [m/s] (min, max; drawn per frame): a person
#: carrying the rig through a corridor, as every procedural-world dataset's.
REFERENCE_SPEED_MPS = WALKING_SPEED_MPS


def reference_spec(frames_per_world: int = 10, radar: Any = REFERENCE_RADAR, world: Any = None,
                   rig: Any = None, seed: int = 0, labels: Any = None,
                   speed_mps: tuple[float, float] = REFERENCE_SPEED_MPS) -> DatasetSpec:
    """The :class:`~sim2radar.factory.spec.DatasetSpec` of a reference dataset: ground-truth
    geometry, the reference radar on a rig walking at ``speed_mps`` (min, max) [m/s] along its
    heading (a speed drawn per frame), no RGB / LiDAR rendering."""
    return DatasetSpec(frames_per_world=frames_per_world, geometry="ground_truth", radar=radar,
                       world=world, rig=rig, seed=seed, labels=labels, render_rgb=False,
                       motion={"speed_mps": list(speed_mps)})


class ReferenceRequest(BaseModel):
    """One run of the ``reference`` job.

    Attributes
    ----------
    store : artifact store root (local path or fsspec URI)
    dataset : manifest name
    export_dir : OpenPCDet export folder, or None
    first_seed : seed of the first world (keep it disjoint from the simulated domain's worlds)
    worlds : number of worlds of ``frames_per_world`` frames (None: sized like the paper's
        371 / 92 / 155 split, :func:`~sim2radar.factory.reference.plan_reference`)
    frames_per_world : frames along each world's trajectory
    radar : the reference radar (preset name, YAML path or RadarConfig fields)
    seed : run seed (trajectories, radar noise, splits)
    speed_mps : the rig's walking speed range [m/s] (min, max; drawn per frame)
    force, strict : as the ``generate`` job's
    run : how many worlds at once, and where (:class:`~sim2radar.tasks.runner.RunOptions`)
    """

    model_config = ConfigDict(extra="forbid")

    store: str = "out/store"
    dataset: str = "reference"
    export_dir: str | None = None
    first_seed: int = REFERENCE_FIRST_SEED
    worlds: int | None = Field(None, ge=1)
    frames_per_world: int = Field(10, ge=1)
    radar: str | dict = REFERENCE_RADAR
    seed: int = 0
    speed_mps: tuple[float, float] = REFERENCE_SPEED_MPS
    force: bool = False
    strict: bool = False
    run: RunOptions = RunOptions()

    def plan(self):
        """The :class:`~sim2radar.factory.reference.ReferencePlan`: worlds, frames, splits."""
        return plan_reference(self.first_seed, worlds=self.worlds,
                              frames_per_world=self.frames_per_world, seed=self.seed)

    def generate_request(self) -> GenerateRequest:
        """The ``generate`` job's request that makes this reference dataset (the spec is
        validated here: a bad radar fails before any work)."""
        from sim2radar.storage.worlds import world_id_for

        plan = self.plan()
        return GenerateRequest(
            spec=reference_spec(self.frames_per_world, self.radar, seed=self.seed,
                                speed_mps=self.speed_mps),
            seeds=list(plan.seeds), store=self.store, dataset=self.dataset,
            export_dir=self.export_dir, force=self.force, strict=self.strict,
            frames_by_seed=plan.frames_by_seed,
            splits={k: [world_id_for(s) for s in v] for k, v in plan.splits.items()},
            export_doppler=True, domain=DOMAIN_LABEL, run=self.run)


def reference_dataset(request: ReferenceRequest, runner: Runner) -> RunSummary:
    """Build (or find cached) a reference dataset; returns the ``generate`` job's summary
    plus ``plan`` (frames per split)."""
    summary = generate_dataset(request.generate_request(), runner)
    summary["plan"] = request.plan().split_frames()
    return summary
