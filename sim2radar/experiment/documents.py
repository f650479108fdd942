"""The JSON documents of a sweep folder as types (:class:`~.folder.SweepFolder` reads and writes
them): ``sweep.json`` (:class:`SweepDocument`) and ``progress.json`` (:class:`SweepProgress`).

Their JSON is what it was when they were plain dicts (the same keys in the same order), so
folders written before still load; fields a later version added have defaults, and fields this
version does not know (e.g. ``packing``, written by ``--runs-per-gpu``) are kept. A document
is written back as it was read: a field it did not hold is not added (its default only reads).

:func:`parse_document` turns a file's JSON value into its type, or raises
:class:`DocumentError` saying in one line what is wrong with it (not an object, a field of
another type, a ``sweep.json`` whose settings were deleted).

The folder's other JSON files stay dicts: ``stats.json`` (:func:`~.stats.sweep_statistics`'
nested tables, whose readers check the parts they use), ``gap/gap.json`` (the gap report's
figures and numbers) and ``generation.json`` (the generators' summaries) are open-ended;
``plan.json`` is :class:`~.plan.SweepPlan`'s.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any, TypeVar

from pydantic import (
    BaseModel,
    ConfigDict,
    ValidationError,
    field_validator,
    model_serializer,
    model_validator,
)

__all__ = ["DocumentError", "SweepDocument", "SweepProgress", "parse_document"]

#: the longest value an error message quotes [characters]
_SHOWN_CHARS = 60


class DocumentError(ValueError):
    """A folder document that cannot be read as its type.

    Attributes
    ----------
    path : str — the file.
    problem : str — what is wrong, one line (``holds list, not the sweep's document``).
    fix : str — what to do about it; a caller with a better remedy for its own context
        words its message from ``path`` and ``problem``.
    """

    def __init__(self, path: str | os.PathLike, problem: str, fix: str) -> None:
        self.path, self.problem, self.fix = os.fspath(path), problem, fix
        super().__init__(f"{self.path}: {problem}; {fix}")


class _Document(BaseModel):
    """A folder document: frozen, unknown fields kept, written back with the fields it holds."""

    model_config = ConfigDict(frozen=True, extra="allow")

    @model_serializer(mode="wrap")
    def _as_written(self, handler) -> dict[str, Any]:
        held = self.model_fields_set | set(self.model_extra or ())
        return {k: v for k, v in handler(self).items() if k in held}

    def held(self, field: str) -> Any:
        """``field``'s value where the document holds it, None where it does not (an older
        file without it: its default is not what that sweep wrote)."""
        if field in self.model_fields_set or field in (self.model_extra or {}):
            return getattr(self, field)
        return None


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
    settings : dict — :func:`~.plan.protocol_settings` (None: a sweep prepared before settings
        were recorded; never null in the file); settings_digest : str — its digest.
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

    @field_validator("settings", mode="before")
    @classmethod
    def _settings_document(cls, value: Any) -> Any:
        # absent (None, the default) is a sweep from before settings were recorded; a null or
        # any other value written in their place is a damaged file, not a skipped check
        if not isinstance(value, Mapping):
            raise ValueError(f"field 'settings' is {_shown(value)}, not the settings document "
                             "the sweep wrote")
        return value

    @model_validator(mode="after")
    def _digest_has_settings(self) -> SweepDocument:
        if self.settings is None and self.settings_digest is not None:
            raise ValueError(f"it has a settings digest ({self.settings_digest}) but no "
                             "settings: the file was edited")
        return self


class SweepProgress(_Document):
    """``progress.json``: how far a running sweep is (rewritten as each job finishes; the live
    dashboard polls it).

    Attributes
    ----------
    total_runs, finished, failed : int — fine-tuning runs planned, finished (any status),
        failed.
    total_pretrainings, pretrainings_finished : int — the same for pre-trainings.
    running : list — what is training now, one entry each (text, or a value the dashboard
        shows as JSON), for a writer that knows; the sweep flow writes none.
    updated_at : str — UTC ISO-8601 time of the last update.
    """

    total_runs: int
    finished: int
    failed: int
    total_pretrainings: int = 0
    pretrainings_finished: int = 0
    running: list[Any] = []
    updated_at: str = ""


_D = TypeVar("_D", bound=_Document)
#: what a document's type is called in an error message
_WHAT = {SweepDocument: "the sweep's document", SweepProgress: "the sweep's progress"}


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= _SHOWN_CHARS else text[:_SHOWN_CHARS - 3] + "..."


def parse_document(kind: type[_D], value: Any, path: str | os.PathLike, fix: str) -> _D:
    """``value`` (a file's JSON value) as the document ``kind``.

    Parameters
    ----------
    kind : :class:`SweepDocument` or :class:`SweepProgress`.
    value : the parsed JSON of ``path``.
    path : the file, for the message; fix : the remedy the message ends with.

    Raises
    ------
    DocumentError — ``value`` is not a JSON object, or a field is missing or of another type
        (the first such field, dotted: ``field 'fractions.1' is 'a': Input should be a valid
        number...``), or the document contradicts itself.
    """
    if not isinstance(value, dict):
        raise DocumentError(path, f"holds {type(value).__name__}, not {_WHAT[kind]}", fix)
    try:
        return kind.model_validate(value)
    except ValidationError as exc:
        err = exc.errors(include_url=False)[0]
        if err["type"] == "value_error":       # the validators above word their own
            problem = str(err["ctx"]["error"])
        else:
            where = ".".join(str(p) for p in err["loc"])
            problem = (f"field {where!r} is missing" if err["type"] == "missing" else
                       f"field {where!r} is {_shown(err['input'])}: {err['msg']}")
        raise DocumentError(path, problem, fix) from None
