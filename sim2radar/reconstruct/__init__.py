"""Reconstruction from RGB (paper §3): depth -> segments + labels -> materials -> 3D scene.

Importing this package registers every backend:

=========  ===========================  =====================  ==============
stage      production (user weights)    built-in (no weights)  ground truth
=========  ===========================  =====================  ==============
depth      ``moge`` (ONNX)              ``lidar``              ``oracle``
segments   ``sam2-gdino`` (ONNX)        ``builtin``            ``oracle``
materials  ``vlm`` (OpenAI-compatible)  ``prior``              ``oracle``
=========  ===========================  =====================  ==============

Modules whose optional dependency is missing still register their name; using the backend then
raises an ``ImportError`` that says what to install.
"""

from __future__ import annotations

import importlib
import logging

from sim2radar.reconstruct.types import (
    DEPTH_BACKENDS,
    MATERIAL_BACKENDS,
    SEGMENT_BACKENDS,
    DepthResult,
    FrameInput,
    MaterialLabel,
    ReconstructionInputError,
    Segments,
    up_from_pitch_roll,
)

log = logging.getLogger(__name__)

# (module, registry, backend name) — core modules first, then the production backends.
_BACKEND_MODULES = (
    ("depth_oracle", DEPTH_BACKENDS, "oracle"),
    ("depth_lidar", DEPTH_BACKENDS, "lidar"),
    ("depth_moge", DEPTH_BACKENDS, "moge"),
    ("segment_builtin", SEGMENT_BACKENDS, "builtin"),
    ("segment_oracle", SEGMENT_BACKENDS, "oracle"),
    ("segment_sam2_gdino", SEGMENT_BACKENDS, "sam2-gdino"),
    ("materials_prior", MATERIAL_BACKENDS, "prior"),
    ("materials_oracle", MATERIAL_BACKENDS, "oracle"),
    ("materials_vlm", MATERIAL_BACKENDS, "vlm"),
)


def _unavailable(name: str, module: str, error: BaseException) -> type:
    message = (
        f"backend {name!r} is unavailable: importing sim2radar.reconstruct.{module} failed with "
        f"{type(error).__name__}: {error}. Install the missing package (see README) and retry."
    )

    class Unavailable:
        def __init__(self, *args, **kwargs) -> None:
            raise ImportError(message)

        def check(self) -> str:  # so ``sim2radar models check`` constructs it and reports why
            raise ImportError(message)

    Unavailable.__name__ = f"Unavailable_{module}"
    Unavailable.__doc__ = message
    return Unavailable


for _module, _registry, _name in _BACKEND_MODULES:
    try:
        importlib.import_module(f"sim2radar.reconstruct.{_module}")
    except ImportError as _exc:  # optional dependency missing, or module not written yet
        log.debug("reconstruction backend module %s not importable: %s", _module, _exc)
        if _name not in _registry:
            _registry.register(_name)(_unavailable(_name, _module, _exc))

from sim2radar.reconstruct.pipeline import (  # noqa: E402
    BackendSpec,
    LabeledScene,
    ReconstructionConfig,
    build_backends,
    reconstruct,
)

__all__ = [
    "DEPTH_BACKENDS",
    "SEGMENT_BACKENDS",
    "MATERIAL_BACKENDS",
    "FrameInput",
    "up_from_pitch_roll",
    "DepthResult",
    "Segments",
    "MaterialLabel",
    "ReconstructionInputError",
    "BackendSpec",
    "ReconstructionConfig",
    "LabeledScene",
    "reconstruct",
    "build_backends",
]
