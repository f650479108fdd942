"""Reconstruction of RGB [+ LiDAR] frames into the artifact store: the ``reconstruct`` job's
driver :func:`reconstruct_images` (``sim2radar reconstruct``; the flow
:mod:`sim2radar.flows.reconstruct` runs it with Prefect) and its unit of work, one frame.

Per image, :func:`reconstruct_image`:

1. digests the image bytes (+ LiDAR) and keys both artifacts (``reconstruction`` and
   ``scene_meshes``) on that digest + the resolved :class:`ReconstructionConfig`
   (:func:`sim2radar.storage.reconstruction.write_scene_artifacts`);
2. if both exist: status ``skipped`` (resume, no recompute);
3. otherwise runs the four stages and publishes both artifacts atomically with provenance
   (status ``ok``), plus the stage sheet PNG and a ``scene.yaml`` folder when asked.

Errors propagate (the runner records the frame as ``failed`` in the manifest and the others
finish). No retries: reconstruction is deterministic; the VLM backend retries its own HTTP
calls.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import os
import time
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from sim2radar.reconstruct.pipeline import STAGE_VERSION, ReconstructionConfig
from sim2radar.tasks.common import Outcome, RunSummary, jsonable, open_store, summarize
from sim2radar.tasks.runner import Runner, RunOptions, StepRun, Units

__all__ = [
    "RECONSTRUCTION_STAGE_VERSION",
    "ImageJob",
    "reconstruct_image",
    "ReconstructRequest",
    "reconstruct_images",
    "failed_outcome",
]

log = logging.getLogger(__name__)

#: The reconstruction output's version (bumped in the pipeline when the output of the same
#: inputs changes).
RECONSTRUCTION_STAGE_VERSION = STAGE_VERSION


@dataclasses.dataclass(frozen=True)
class ImageJob:
    """One frame to reconstruct: image file, intrinsics YAML, optional (N, 3) LiDAR ``.npy``."""

    image: str
    intrinsics: str
    lidar: str | None = None

    @property
    def name(self) -> str:
        return Path(self.image).stem


def _inputs(job: ImageJob):
    from sim2radar.camera import CameraIntrinsics
    from sim2radar.reconstruct import FrameInput
    from sim2radar.reconstruct.inputs import load_image, load_lidar, load_rig_calibration
    from sim2radar.storage.reconstruction import frame_input_digests

    rgb = load_image(Path(job.image))
    k = CameraIntrinsics.from_yaml(job.intrinsics)
    rig = load_rig_calibration(Path(job.intrinsics))
    pts, note = load_lidar(Path(job.lidar)) if job.lidar else (None, "")
    inputs = frame_input_digests(FrameInput(rgb, k, pts, name=job.name, **rig))
    return rgb, k, pts, rig, note, inputs


def reconstruct_image(
    job: ImageJob,
    store,
    config: ReconstructionConfig | dict | None = None,
    *,
    out_dir: str | None = None,
    force: bool = False,
    sheet_dir: str | os.PathLike | None = None,
    backends: tuple | None = None,
) -> Outcome:
    """Reconstruct one frame into ``store`` (skips if its artifacts exist, unless ``force``).

    Parameters
    ----------
    job : ImageJob
    store : path/URI or :class:`storage.ArtifactStore`
    config : ReconstructionConfig, or its fields as a dict (default: the builtin preset).
    out_dir : str, optional — where ``sheets/<name>.png`` and ``scenes/<name>/scene.yaml`` go.
    sheet_dir : where ``<name>.png`` goes instead of ``out_dir/sheets``.
    backends : the config's backends, built once for many frames
        (:func:`sim2radar.reconstruct.build_backends`; default: built here).
    """
    from sim2radar.reconstruct import FrameInput, reconstruct
    from sim2radar.storage.reconstruction import reconstruction_keys, write_scene_artifacts
    from sim2radar.tasks.steps import material_fallbacks

    t0 = time.perf_counter()
    st = open_store(store)
    cfg = ReconstructionConfig.model_validate(config or {})
    cfg_dict = cfg.to_dict()
    rgb, k, pts, rig, note, inputs = _inputs(job)
    keys = reconstruction_keys(inputs, cfg_dict, stage_version=RECONSTRUCTION_STAGE_VERSION)
    if not force and st.all_cached(keys):  # a provisional (fallback) scene is made again
        return Outcome(job.name, "skipped", artifacts=keys, source=job.image,
                       timings_s={"total": time.perf_counter() - t0})
    if force:
        for s, key in keys.items():
            st.delete(s, key)
    scene = reconstruct(FrameInput(rgb, k, pts, name=job.name, **rig), cfg, backends=backends)
    if note:
        scene.info["fallbacks"].append(note)
    provisional = material_fallbacks(scene.segment_materials)
    written = write_scene_artifacts(st, scene, inputs=inputs, config=cfg_dict,
                                    stage_version=RECONSTRUCTION_STAGE_VERSION,
                                    provisional=provisional)
    if out_dir:
        scene.write_scene(Path(out_dir) / "scenes" / job.name)
    if out_dir or sheet_dir:
        from sim2radar.reconstruct.sheet import stage_sheet

        sheets = Path(sheet_dir) if sheet_dir else Path(out_dir) / "sheets"
        stage_sheet(scene, sheets / f"{job.name}.png", lidar_points=pts)
    timings = {k: float(v) for k, v in scene.timings_s.items()}
    timings["task_total"] = time.perf_counter() - t0
    labels = {lbl: scene.segment_labels.count(lbl) for lbl in sorted(set(scene.segment_labels))}
    return Outcome(job.name, "ok", artifacts=written, timings_s=timings, source=job.image,
                   measured={"summary": jsonable({"segments": labels, "meshes": len(scene.meshes),
                                          "door_boxes": len(scene.door_boxes),
                                          "fallbacks": scene.info["fallbacks"]}),
                             "fallbacks": (provisional or {}).get("fallbacks", 0)})


class ReconstructRequest(BaseModel):
    """One run of the ``reconstruct`` job: RGB [+ LiDAR] frames into material-labelled scenes.

    Attributes
    ----------
    jobs : the frames (image, intrinsics YAML, optional LiDAR ``.npy``)
    store : artifact store root (local path or fsspec URI)
    dataset : manifest name
    config : the reconstruction's backends and settings (None: the built-in preset)
    out_dir : where ``sheets/<name>.png`` and ``scenes/<name>/scene.yaml`` go, or None
    sheet_dir : where ``<name>.png`` goes instead of ``out_dir/sheets``
    force : recompute frames even when cached
    run : how many frames at once (:class:`~sim2radar.tasks.runner.RunOptions`)
    """

    model_config = ConfigDict(extra="forbid")

    jobs: list[ImageJob] = Field(min_length=1)
    store: str = "out/store"
    dataset: str = "reconstruction"
    config: ReconstructionConfig | None = None
    out_dir: str | None = None
    sheet_dir: str | None = None
    force: bool = False
    run: RunOptions = RunOptions()


def _frame_unit(job: ImageJob, run: StepRun, *, request: ReconstructRequest,
                backends: tuple | None) -> Outcome:
    return reconstruct_image(job, request.store, request.config, out_dir=request.out_dir,
                             force=request.force, sheet_dir=request.sheet_dir,
                             backends=backends)


def reconstruct_images(request: ReconstructRequest, runner: Runner, *,
                       backends: tuple | None = None) -> RunSummary:
    """The ``reconstruct`` job: every frame of ``request`` recorded in the dataset manifest as
    ``ok``, ``skipped`` (cached) or ``failed`` (with its error) while the others finish.
    ``backends``: the config's backends built once for every frame (one process; a Prefect
    run on Dask builds them per frame).

    Returns
    -------
    dict — :func:`~sim2radar.tasks.common.summarize`'s (``outcomes``: the frames)
    """
    units = Units(job="reconstruct", what="frame", task="reconstruct-image",
                  items=tuple(request.jobs),
                  work=functools.partial(_frame_unit, request=request, backends=backends),
                  failed=failed_outcome, name=lambda job: job.name,
                  store=request.store, dataset=request.dataset)
    return summarize(request.store, request.dataset, runner.run(units))


def failed_outcome(job: ImageJob, error: BaseException | str) -> Outcome:
    """A ``failed`` outcome of ``job`` with ``"Type: message"`` error text."""
    return Outcome.failed(job.name, error, source=job.image)
