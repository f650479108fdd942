"""The ``sim2radar`` command line.

Each stage's commands live in their own module and register on the shared Typer ``app``.
Heavy imports (Prefect, Mitsuba, torch) happen inside the commands, so ``sim2radar --help``
stays fast. Commands that run flows import from ``flows`` lazily: the library itself never
imports Prefect.
"""

from __future__ import annotations

from sim2radar.cli._app import app, finish

# Registration imports: each module adds its commands to ``app``.
from sim2radar.cli import info as _info  # noqa: E402,F401  isort: skip
from sim2radar.cli import simulate as _simulate  # noqa: E402,F401  isort: skip
from sim2radar.cli import worlds as _worlds  # noqa: E402,F401  isort: skip
from sim2radar.cli import detect as _detect  # noqa: E402,F401  isort: skip
from sim2radar.cli import reconstruct as _reconstruct  # noqa: E402,F401  isort: skip
from sim2radar.cli import generate as _generate  # noqa: E402,F401  isort: skip
from sim2radar.cli import captures as _captures  # noqa: E402,F401  isort: skip
from sim2radar.cli import reference as _reference  # noqa: E402,F401  isort: skip
from sim2radar.cli import experiment as _experiment  # noqa: E402,F401  isort: skip
from sim2radar.cli import demo as _demo  # noqa: E402,F401  isort: skip
from sim2radar.cli import gap as _gap  # noqa: E402,F401  isort: skip
from sim2radar.cli import dashboard as _dashboard  # noqa: E402,F401  isort: skip
from sim2radar.cli import server as _server  # noqa: E402,F401  isort: skip
from sim2radar.cli import models as _models  # noqa: E402,F401  isort: skip
from sim2radar.cli import store as _store  # noqa: E402,F401  isort: skip
from sim2radar.cli import importing as _importing  # noqa: E402,F401  isort: skip
from sim2radar.cli import config as _config  # noqa: E402,F401  isort: skip
from sim2radar.cli import deploy as _deploy  # noqa: E402,F401  isort: skip

__all__ = ["app", "main"]


def main() -> None:
    """Console-script entry point: the command, then :func:`~sim2radar.cli._app.finish` with
    its exit status (an exception other than an exit propagates as usual)."""
    try:
        app()
    except SystemExit as exc:
        finish(exc.code)
    finish(0)
