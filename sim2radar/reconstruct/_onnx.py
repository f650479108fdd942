"""onnxruntime helpers for the production backends: load a user-supplied ``.onnx`` with clear errors.

onnxruntime is imported lazily, so importing the backends never needs it.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["OnnxModel", "ModelSignatureError", "file_sha256"]


class ModelSignatureError(ValueError):
    """The ONNX graph's inputs/outputs are not the ones the backend expects."""


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file (model provenance)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def _default_providers() -> list[str]:
    import onnxruntime as ort

    available = ort.get_available_providers()
    preferred = [p for p in ("CUDAExecutionProvider", "CPUExecutionProvider") if p in available]
    return preferred or available


class OnnxModel:
    """An onnxruntime session over a user-supplied model file, checked against a signature.

    Parameters
    ----------
    path : str | Path — the ``.onnx`` file.
    what : str — human name used in errors, e.g. ``"MoGe-2 (depth backend 'moge', option
        model_path)"``.
    inputs : names the graph must accept (each must be a graph input).
    outputs : names the graph must produce.
    optional_inputs : names fed only when the graph declares them.
    providers : onnxruntime execution providers; default CUDA if available, then CPU.
    """

    def __init__(
        self,
        path: str | Path | None,
        what: str,
        inputs: Sequence[str],
        outputs: Sequence[str],
        optional_inputs: Sequence[str] = (),
        providers: Sequence[str] | None = None,
        threads: int | None = None,
    ) -> None:
        if path is None or str(path) == "":
            raise FileNotFoundError(f"{what}: no model file given; set it to your exported .onnx")
        self.path = Path(path).expanduser()
        if not self.path.is_file():
            raise FileNotFoundError(
                f"{what}: model file {self.path} not found; export the model to ONNX (README, "
                "'Plugging in real models', gives each model's recipe) and set its path"
            )
        try:
            import onnxruntime as ort
        except ImportError as exc:  # pragma: no cover - onnxruntime is a dependency
            raise ImportError(f"{what}: needs onnxruntime (pip install onnxruntime)") from exc
        opts = ort.SessionOptions()
        if threads:
            opts.intra_op_num_threads = int(threads)
        opts.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(
                str(self.path), sess_options=opts,
                providers=list(providers) if providers else _default_providers(),
            )
        except Exception as exc:
            raise ModelSignatureError(
                f"{what}: onnxruntime cannot load {self.path}: {exc}"
            ) from None
        self.what = what
        self.input_names = [i.name for i in self.session.get_inputs()]
        self.output_names = [o.name for o in self.session.get_outputs()]
        missing_in = [n for n in inputs if n not in self.input_names]
        missing_out = [n for n in outputs if n not in self.output_names]
        if missing_in or missing_out:
            raise ModelSignatureError(
                f"{what}: {self.path.name} does not have the expected signature: missing "
                f"inputs {missing_in or '-'}, missing outputs {missing_out or '-'}; the graph has "
                f"inputs {self.input_names} and outputs {self.output_names}. Re-export with the "
                "documented names or set the backend's input/output name options"
            )
        allowed = set(inputs) | set(optional_inputs)
        extra = [n for n in self.input_names if n not in allowed]
        if extra:
            raise ModelSignatureError(
                f"{what}: {self.path.name} has inputs {extra} this backend does not feed; "
                f"expected {list(inputs)} (+ optional {list(optional_inputs)})"
            )
        self.sha256 = file_sha256(self.path)

    def has_input(self, name: str) -> bool:
        return name in self.input_names

    def input_shape(self, name: str) -> list:
        for i in self.session.get_inputs():
            if i.name == name:
                return list(i.shape)
        raise KeyError(name)

    def input_type(self, name: str) -> str:
        for i in self.session.get_inputs():
            if i.name == name:
                return i.type
        raise KeyError(name)

    def output_type(self, name: str) -> str:
        for o in self.session.get_outputs():
            if o.name == name:
                return o.type
        raise KeyError(name)

    def run(self, feeds: dict[str, np.ndarray], outputs: Sequence[str]) -> dict[str, np.ndarray]:
        feeds = {k: v for k, v in feeds.items() if k in self.input_names}
        try:
            values = self.session.run(list(outputs), feeds)
        except Exception as exc:
            shapes = {k: (tuple(v.shape), str(v.dtype)) for k, v in feeds.items()}
            raise ModelSignatureError(
                f"{self.what}: running {self.path.name} failed with inputs {shapes}: {exc}"
            ) from None
        return dict(zip(outputs, values, strict=True))


def onnx_dtype(type_str: str) -> type:
    """numpy dtype for an onnxruntime type string like ``tensor(int64)``."""
    table = {
        "tensor(float)": np.float32,
        "tensor(double)": np.float64,
        "tensor(int64)": np.int64,
        "tensor(int32)": np.int32,
        "tensor(bool)": np.bool_,
        "tensor(float16)": np.float16,
    }
    return table.get(type_str, np.float32)
