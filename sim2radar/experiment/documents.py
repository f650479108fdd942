"""The JSON documents of a sweep folder as types (:class:`~.folder.SweepFolder` reads and writes
them): ``sweep.json`` (:class:`SweepDocument`) and ``progress.json`` (:class:`SweepProgress`).

Their JSON is what it was when they were plain dicts (the same keys in the same order), so
folders written before still load; fields a later version added have defaults, and fields this
version does not know (e.g. ``packing``, written by ``--runs-per-gpu``) are kept. A document
is written back as it was read: a field it did not hold is not added (its default only reads).
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, model_serializer

__all__ = ["SweepDocument", "SweepProgress"]


class _Document(BaseModel):
    """A folder document: frozen, unknown fields kept, written back with the fields it holds."""

    model_config = ConfigDict(frozen=True, extra="allow")

    @model_serializer(mode="wrap")
    def _as_written(self, handler) -> dict[str, Any]:
        held = self.model_fields_set | set(self.model_extra or ())
        return {k: v for k, v in handler(self).items() if k in held}


class SweepDocument(_Document):
    """``sweep.json``: what a sweep is (written when it is prepared; what the dashboard, the
    report and the tracker read).

    Attributes
    ----------
    name : str — the sweep's name.
    profile : dict — its :class:`~.profiles.ExperimentProfile` after overrides
        (``model_dump(mode="json")``; kept as written, so an older profile's fields still read).
    conditions : list of str — its conditions, baseline first.
    fractions : list of float — real-data fractions; trials : int — trials per cell.
    metric : str — the AP column the statistics compare.
    datasets : dict — role -> the dataset's description (root, domain, digest, splits).
    real_domain : str; real_is_proxy : bool — what the real dataset is.
    intensity_match : dict — pre-training id -> its intensity mapping's dict form.
    n_pretrains, n_runs : int — jobs planned.
    provenance : dict — ``versions``, ``code``, ``git`` and both stages' ``configs``.
    settings : dict — :func:`~.plan.protocol_settings`; settings_digest : str — its digest.
    settings_fixed_at, created_at : str — UTC ISO-8601 times.
    precision : dict — the stages' mixed-precision decisions.
    preregistration : dict or None — ``file``, ``sha256`` and ``source`` of its copy.
    """

    name: str
    profile: dict[str, Any] = {}
    conditions: list[str] = []
    fractions: list[float] = []
    trials: int = 0
    metric: str = ""
    datasets: dict[str, dict[str, Any]] = {}
    real_domain: str = ""
    real_is_proxy: bool | None = None
    intensity_match: dict[str, dict[str, Any]] = {}
    n_pretrains: int = 0
    n_runs: int = 0
    provenance: dict[str, Any] = {}
    settings: dict[str, Any] | None = None
    settings_digest: str | None = None
    settings_fixed_at: str | None = None
    created_at: str | None = None
    precision: dict[str, Any] = {}
    preregistration: dict[str, Any] | None = None


class SweepProgress(_Document):
    """``progress.json``: how far a running sweep is (rewritten as each job finishes; the live
    dashboard polls it).

    Attributes
    ----------
    total_runs, finished, failed : int — fine-tuning runs planned, finished (any status),
        failed.
    total_pretrainings, pretrainings_finished : int — the same for pre-trainings.
    updated_at : str — UTC ISO-8601 time of the last update.
    """

    total_runs: int
    finished: int
    failed: int
    total_pretrainings: int = 0
    pretrainings_finished: int = 0
    updated_at: str = ""
