"""Task helpers shared by every stage (no Prefect import: ``--no-prefect`` runs never load it):
the one :class:`Outcome` record with its manifest :func:`record` and run :func:`summarize`,
store handles, the retry policy of storage I/O. How units of work run is
:mod:`sim2radar.tasks.runner`.

Plain functions (no Prefect engine needed) so tests call them directly.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import re
from collections.abc import Iterable, Sequence
from typing import Any, NotRequired, TypedDict

from sim2radar.fileio import jsonable
from sim2radar.storage import ArtifactStore, is_transient_io_error
from sim2radar.storage.manifest import MANIFESTS, STATUSES
from sim2radar.vocab import Status

__all__ = [
    "FRAME_ROW",
    "Outcome",
    "Status",
    "RunSummary",
    "StatusCounts",
    "FallbackCounts",
    "count_statuses",
    "count_fallbacks",
    "record",
    "summarize",
    "failed_scene_ids",
    "open_store",
    "REMOTE_IO_RETRIES",
    "REMOTE_IO_RETRY_DELAYS_S",
    "retry_transient_io",
    "jsonable",
]

log = logging.getLogger(__name__)

#: Prefect retries for tasks whose work is storage I/O (remote object stores can flake).
#: Simulation tasks get none: a deterministic failure would only fail again.
REMOTE_IO_RETRIES = 3
#: Backoff between those retries [s].
REMOTE_IO_RETRY_DELAYS_S = [1.0, 4.0, 16.0]


def retry_transient_io(task, task_run, state) -> bool:
    """Prefect ``retry_condition_fn`` of every task retried with :data:`REMOTE_IO_RETRIES`:
    retry only errors that can flake (:func:`storage.is_transient_io_error`: timeouts, dropped
    connections), never ones that repeat on every attempt (a read-only or unwritable store,
    a full disk, a missing file, a schema or value error), which fail at once."""
    exc = state.data if isinstance(state.data, BaseException) else None
    if exc is None:
        try:
            exc = state.result(raise_on_failure=False)
        except Exception:  # noqa: BLE001 - an unreadable result is not a reason to retry
            return False
    return isinstance(exc, BaseException) and is_transient_io_error(exc)


@dataclasses.dataclass
class Outcome:
    """What happened to one unit of work of any stage — a scene, an image, a world, a capture
    scene or one of their frames — as its manifest row records it.

    Attributes
    ----------
    id : str — the manifest row's ``scene_id`` (``world_000007``, ``world_000007_f002``,
        a scene's name, an image's stem)
    status : Status — ``ok`` (computed), ``skipped`` (all cached) or ``failed``
        (:data:`~sim2radar.storage.manifest.STATUSES`)
    error : str — ``"ExceptionType: message"`` when failed (a world: or a count of failed frames)
    artifacts : dict — stage -> content key
    timings_s : dict — step -> seconds (compute time; cached artifacts report theirs)
    source : str — where the work came from (a scene's YAML, an image, ``sim2radar.worlds seed=7``)
    seed : int — world seed (-1: none)
    index : int — a frame's index in its world or scene (-1: not a frame)
    measured : dict — what the stage measured, by name: ``n_points`` (a frame: geometry ->
        points; a radar scene: points per frame), ``n_labels``, ``n_gt_doors``,
        ``gt_points_near``, ``comparison``, ``label_match`` (a dataset frame: see
        :func:`sim2radar.evaluate.dataset.geometry_metrics`), ``n_frames`` and
        ``doors_visible`` (a world render), ``locations`` and ``pngs`` (files written),
        ``summary`` (a reconstruction)
    parts : list[Outcome] — a world's or capture scene's frames, each a manifest row of its own
    """

    id: str
    status: Status
    error: str = ""
    artifacts: dict[str, str] = dataclasses.field(default_factory=dict)
    timings_s: dict[str, float] = dataclasses.field(default_factory=dict)
    source: str = ""
    seed: int = -1
    index: int = -1
    measured: dict[str, Any] = dataclasses.field(default_factory=dict)
    parts: list[Outcome] = dataclasses.field(default_factory=list)

    @classmethod
    def failed(cls, id: str, error: BaseException | str, **fields: Any) -> Outcome:
        """A ``failed`` outcome; an exception becomes ``"Type: message"``."""
        text = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
        return cls(id, "failed", error=text, **fields)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict (what a flow returns and a summary lists)."""
        d = jsonable({f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                      if f.name != "parts"})
        d["parts"] = [p.to_dict() for p in self.parts]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Outcome:
        """The outcome of :meth:`to_dict`'s dict (e.g. from a flow's returned summary)."""
        return cls(**{**d, "parts": [cls.from_dict(p) for p in d.get("parts", ())]})


class StatusCounts(TypedDict):
    """Units of work by what became of them."""

    ok: int
    skipped: int
    failed: int


class FallbackCounts(TypedDict):
    """Material labels that fell back to ``unknown`` (:func:`count_fallbacks`)."""

    segments: int
    frames: int
    scenes: int


class RunSummary(TypedDict):
    """What a job returns (its flow's result, what the CLI prints and ``--json`` writes): a
    JSON document, so Prefect stores it as the run's result, declared here once.

    The common part is :func:`summarize`'s; a job adds its own keys (each job's driver says
    which): the ``simulate`` job ``radar``; dataset jobs (:func:`sim2radar.tasks.dataset.
    summarize_dataset`) ``frame_counts``, ``geometry``, ``seconds_per_frame``, ``comparison``,
    ``stage_table``, ``export``; the CLI ``pngs``; the reference job ``plan``; a capture run
    ``unit``, ``ground_truth``, ``wall_s``.
    """

    store: str
    dataset: str
    counts: StatusCounts
    fallbacks: FallbackCounts
    outcomes: list[dict[str, Any]]  # Outcome.to_dict() each, in the order of the units
    manifest: str
    radar: NotRequired[str]
    frame_counts: NotRequired[StatusCounts]
    geometry: NotRequired[dict[str, dict[str, Any]]]
    seconds_per_frame: NotRequired[dict[str, float]]
    comparison: NotRequired[dict[str, Any]]
    stage_table: NotRequired[list[dict[str, Any]]]
    export: NotRequired[dict[str, Any]]
    pngs: NotRequired[list[str]]
    plan: NotRequired[dict[str, Any]]
    unit: NotRequired[str]
    ground_truth: NotRequired[bool]
    wall_s: NotRequired[float]


def count_statuses(outcomes: Iterable[Outcome]) -> StatusCounts:
    """``{ok: n, skipped: n, failed: n}``."""
    statuses = [o.status for o in outcomes]
    return {s: statuses.count(s) for s in STATUSES}


def count_fallbacks(outcomes: Iterable[Outcome]) -> FallbackCounts:
    """``{"segments": n, "frames": n, "scenes": n}``: segments whose material fell back to
    ``unknown`` (a VLM outage, an unusable answer; :attr:`MaterialLabel.fallback`), frames and
    scenes made from them. Their artifacts are provisional: the next run computes them again,
    ``generate --strict`` fails on any."""
    outcomes = list(outcomes)
    return {"segments": sum(int(o.measured.get("fallbacks", 0)) for o in outcomes),
            "frames": sum(int(p.measured.get("fallbacks", 0)) > 0
                          for o in outcomes for p in o.parts),
            "scenes": sum(int(o.measured.get("fallbacks", 0)) > 0 for o in outcomes)}


def record(store: str | os.PathLike | ArtifactStore, dataset: str, outcome: Outcome) -> list[dict]:
    """Upsert the outcome's manifest row and one row per part (frame); returns the rows."""
    m = open_store(store).manifest(dataset)
    rows = [m.upsert(outcome.id, outcome.status, error=outcome.error,
                     artifacts=outcome.artifacts, timings_s=outcome.timings_s,
                     source=outcome.source,
                     fallbacks=int(outcome.measured.get("fallbacks", 0)))]
    for p in outcome.parts:
        rows.append(m.upsert(p.id, p.status, error=p.error, artifacts=p.artifacts,
                             timings_s=p.timings_s, source=p.source or
                             f"{outcome.source} frame={p.index}",
                             fallbacks=int(p.measured.get("fallbacks", 0))))
    return rows


def summarize(store: str | os.PathLike | ArtifactStore, dataset: str,
              outcomes: Sequence[Outcome], **extra: Any) -> RunSummary:
    """The run summary a job returns and the CLI prints (:class:`RunSummary`):
    ``{"store", "dataset", "counts": {ok, skipped, failed}, "fallbacks", "outcomes":
    [Outcome.to_dict()], "manifest"`` (where its rows are)``}`` plus the job's ``extra`` keys.
    """
    st = open_store(store)
    summary = RunSummary(store=st.root, dataset=dataset, counts=count_statuses(outcomes),
                         fallbacks=count_fallbacks(outcomes),
                         outcomes=[o.to_dict() for o in outcomes],
                         manifest=st.join(MANIFESTS, dataset))
    summary.update(extra)  # type: ignore[typeddict-item] - the job's keys, declared above
    return summary


#: A frame's manifest row id: ``<scene or world id>_f<frame index, 3+ digits>``.
FRAME_ROW = re.compile(r"^(.+)_f(\d{3,})$")


def failed_scene_ids(store, dataset: str) -> list[str]:
    """Ids of the scenes (worlds, capture scenes; not their frame rows) the ``dataset``
    manifest records as ``failed``: what ``--retry-failed`` reruns.

    Raises
    ------
    ValueError — the dataset has no manifest rows (naming the store and the datasets it has).
    """
    st = open_store(store)
    rows = st.manifest(dataset).rows()
    if not rows:
        raise ValueError(f"store {st.root}: dataset {dataset!r} has no manifest rows, nothing "
                         f"to retry; known datasets: {st.manifests()}")
    return sorted(r["scene_id"] for r in rows
                  if r["status"] == "failed" and not FRAME_ROW.match(r["scene_id"]))


def open_store(store: str | os.PathLike | ArtifactStore) -> ArtifactStore:
    """An :class:`~storage.ArtifactStore` from a path/URI (or the store itself)."""
    return store if isinstance(store, ArtifactStore) else ArtifactStore(store)
