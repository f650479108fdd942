"""Pre-flight check of the models a reconstruction config names (``sim2radar models check``).

Before a long run: every backend that loads a model file or talks to a server is built from the
config's options (which loads and signature-checks each ``.onnx``) and runs one tiny input — MoGe-2
a 96 × 72 frame, SAM2 one decoder batch and Grounding DINO one detection pass, the VLM backend
``GET {base_url}/models`` compared with its ``model``. Backends without model files (``lidar``,
``builtin``, ``prior``, the ``oracle`` ones) are reported as built-in. Each backend gives one
:class:`BackendCheck`: ok with what ran, or the error, whose message says how to fix it.

A backend takes part by having a ``check() -> str`` method (:class:`SelfCheck`): it returns a
one-line summary or raises.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Protocol, runtime_checkable

from sim2radar.reconstruct.pipeline import ReconstructionConfig
from sim2radar.reconstruct.types import DEPTH_BACKENDS, MATERIAL_BACKENDS, SEGMENT_BACKENDS
from sim2radar.registry import UnknownBackendError

__all__ = ["BUILTIN", "BackendCheck", "SelfCheck", "check_models", "preflight_servers"]

#: What a backend without model files reports.
BUILTIN = "ok (built-in, no model file)"


@runtime_checkable
class SelfCheck(Protocol):
    """A backend that loads model files or talks to a server, and can try them on a tiny input."""

    def check(self) -> str: ...


@dataclasses.dataclass(frozen=True)
class BackendCheck:
    """The check of one stage's backend.

    stage : "depth", "segments" or "materials"; backend : its registry name.
    ok : bool; message : what ran (ok) or what is wrong and how to fix it; seconds : [s].
    """

    stage: str
    backend: str
    ok: bool
    message: str
    seconds: float = 0.0

    def line(self) -> str:
        """One line: ``stage (backend): ok ...`` or ``stage (backend): FAILED: ...``."""
        if self.message == BUILTIN:
            return f"{self.stage} ({self.backend}): {BUILTIN}"
        return f"{self.stage} ({self.backend}): {'ok' if self.ok else 'FAILED'}: {self.message}"


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if isinstance(exc, (ValueError, OSError, ImportError, RuntimeError)) \
        else f"{type(exc).__name__}: {text}"


def check_models(config: ReconstructionConfig) -> list[BackendCheck]:
    """Build each configured backend and run its :meth:`SelfCheck.check`; one result per stage.

    Raises ValueError (before building anything) when a backend name is not registered — a
    config error, not a model's.
    """
    import sim2radar.reconstruct  # noqa: F401  (registers every backend module)

    stages = (("depth", config.depth, DEPTH_BACKENDS),
              ("segments", config.segments, SEGMENT_BACKENDS),
              ("materials", config.materials, MATERIAL_BACKENDS))
    classes = []
    for stage, spec, registry in stages:
        try:
            classes.append(registry.get(spec.name))
        except UnknownBackendError as exc:
            raise ValueError(f"{stage}: {exc.args[0]}") from None
    out = []
    for (stage, spec, _), cls in zip(stages, classes, strict=True):
        if not (isinstance(cls, type) and issubclass(cls, SelfCheck)):
            out.append(BackendCheck(stage, spec.name, True, BUILTIN))
            continue
        t0 = time.perf_counter()
        try:
            message, ok = cls(**dict(spec.options)).check(), True
        except Exception as exc:  # noqa: BLE001 - every failure is one line of the report
            message, ok = _one_line(exc), False
        out.append(BackendCheck(stage, spec.name, ok, message, time.perf_counter() - t0))
    return out


def preflight_servers(config: ReconstructionConfig) -> str | None:
    """Before a run that reconstructs: ask the VLM server (when the materials backend is
    ``vlm``) which models it serves. A server that cannot serve the run at all — key refused,
    or not serving the configured model — is a configuration error: raises ValueError with one
    line naming the fix, before any frame is worked on. A server that cannot be reached is left
    to the run (its retries and ``on_error``); returns that warning as a line (None when all is
    well or there is no server)."""
    from sim2radar.reconstruct.materials_vlm import VlmError, VlmSetupError

    if config.materials.name != "vlm":
        return None
    import sim2radar.reconstruct  # noqa: F401  (registers every backend module)

    backend = MATERIAL_BACKENDS.get("vlm")(**dict(config.materials.options))
    try:
        backend.check()
    except VlmSetupError as exc:
        raise ValueError(f"materials (vlm): {_one_line(exc)}") from None
    except VlmError as exc:
        return f"materials (vlm): {_one_line(exc)}"
    return None
