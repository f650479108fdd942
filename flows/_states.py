"""Run states that tell the truth: a flow whose work failed ends **Failed** in Prefect (an
automation or alert on Failed fires; the message counts what failed), while its caller still
gets the summary of what finished.

    return finish(summary, failed=n_failed, total=n, unit="worlds")   # in a flow body
    summary = run_flow(my_flow, **params)                              # in its caller
"""

from __future__ import annotations

from typing import Any

__all__ = ["WorkFailed", "finish", "finish_run", "run_flow"]


class WorkFailed(RuntimeError):
    """What a flow whose work failed ends with: its message counts the failures,
    ``.summary`` holds what finished. Calling such a flow directly raises it; :func:`run_flow`
    returns the summary instead."""

    def __init__(self, message: str, summary: dict[str, Any]) -> None:
        super().__init__(message)
        self.summary = summary

    def __reduce__(self):  # pickles (Prefect may persist a state's data)
        return (type(self), (str(self), self.summary))


def finish(summary: dict[str, Any], *, failed: int, total: int, unit: str,
           detail: str = "") -> Any:
    """What a flow returns: ``summary`` when nothing failed, else a Failed state whose
    :class:`WorkFailed` carries it, with the message ``"<failed> of <total> <unit>
    failed<detail>"``."""
    if not failed:
        return summary
    from prefect.states import Failed

    message = f"{failed} of {total} {unit} failed{detail}"
    return Failed(message=message, data=WorkFailed(message, summary))


def finish_run(summary: dict[str, Any], unit: str, detail: str = "") -> Any:
    """:func:`finish` for a job's summary (its ``counts``): a flow's return value that ends
    Failed when any of its ``unit`` failed."""
    counts = summary.get("counts") or {}
    return finish(summary, failed=int(counts.get("failed", 0)),
                  total=sum(int(v) for v in counts.values()), unit=unit, detail=detail)


def run_flow(flow: Any, **params: Any) -> Any:
    """Call ``flow`` and return its summary whatever its final state (Completed, or Failed
    carrying a summary); an exception the flow raised is raised here."""
    state = flow(**params, return_state=True)
    result = state.result(raise_on_failure=False)
    if isinstance(result, WorkFailed):
        return result.summary
    if isinstance(result, BaseException):
        raise result
    return result
