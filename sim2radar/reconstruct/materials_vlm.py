"""Stage 3 ``vlm`` backend: material labels from a vision-language model (paper §3 Stage 3).

Any VLM served behind an OpenAI-compatible ``POST {base_url}/chat/completions`` endpoint works;
the reference is InternVL2.5-8B served by vLLM or LMDeploy, e.g.::

    vllm serve OpenGVLab/InternVL2_5-8B --trust-remote-code --limit-mm-per-prompt '{"image": 2}'
    lmdeploy serve api_server OpenGVLab/InternVL2_5-8B --server-port 23333

(a server started from a local folder serves it under the folder's path unless given
``--served-model-name`` (vLLM) / ``--model-name`` (LMDeploy); ``model`` must be a name it serves).

Per segment the backend sends (one request, in a thread pool of ``max_concurrency``):

* a crop of the segment's bounding box (pixels outside the segment dimmed) and, unless
  ``send_context`` is off, the full image downscaled with the segment outlined in red — both as
  base64 PNG ``image_url`` parts;
* a prompt that names the segment's semantic label, lists the material classes, and asks for
  semantic reasoning (fire doors are metal by code, corridor floors are ceramic tile, ...) with a
  JSON answer ``{"material": <one of MATERIAL_CLASSES>, "confidence": 0..1, "reason": "..."}``;
* ``response_format`` (a JSON schema, or ``json_object``) when enabled. A server that rejects it
  with HTTP 400 is asked again without it (remembered for the rest of the run).

Everything the server returns is validated here: the JSON object is extracted from prose or code
fences, the material must be one of ``MATERIAL_CLASSES`` (case, spaces and hyphens normalised; no
synonyms), the confidence is clipped to [0, 1]. An unparseable or out-of-vocabulary answer becomes
``unknown`` with confidence 0, the reason logged and stored in ``MaterialLabel.reason``.

Transport: only the standard library (``urllib``). Timeouts per request; retries with exponential
backoff for timeouts, connection errors, HTTP 5xx and 429 only. When retries are exhausted,
``on_error: raise`` raises :class:`VlmError`; ``on_error: unknown`` records ``unknown`` with the
error as the reason.

A server that cannot serve this run at all stops it with :class:`VlmSetupError` — one line naming
the fix — whatever ``on_error`` says (``on_error`` is for per-segment failures, not for a
misconfigured server, which would otherwise label every segment ``unknown``): HTTP 401/403 (API
key), HTTP 404 (``base_url`` or model name), a model name the server does not list, and HTTP 400
"at most N image(s)" (vLLM's ``--limit-mm-per-prompt``). Before its first request the backend
asks ``GET {base_url}/models`` once and compares ``model`` with the names the server serves.

Cache: valid answers are stored in a small SQLite file (``cache_path``) keyed by
SHA-256(crop PNG, context PNG, semantic label, model, prompt version); a second run on the same
scene makes no request. Bump ``prompt_version`` when you change the prompt.
"""

from __future__ import annotations

import base64
import dataclasses
import hashlib
import http.client
import json
import logging
import os
import re
import sqlite3
import threading
import time
import urllib.error
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Literal

import numpy as np

from sim2radar.reconstruct.types import (
    MATERIAL_BACKENDS,
    DepthResult,
    FrameInput,
    MaterialLabel,
    Segments,
)
from sim2radar.vocab import MATERIAL_CLASSES

__all__ = [
    "PROMPT_VERSION",
    "VlmConfig",
    "VlmError",
    "VlmMaterials",
    "VlmSetupError",
    "ChatClient",
    "AnswerCache",
    "build_prompt",
    "parse_answer",
]

log = logging.getLogger(__name__)

#: Version of the prompt text and answer schema; part of the cache key.
PROMPT_VERSION = "materials-v1"

_MATERIAL_HINTS = (
    "Reason about what the object is and how such objects are built, not only about its colour "
    "or texture. Building practice: doors in corridors, stairwells and fire escapes are fire "
    "doors and therefore metal (steel) by fire code even when painted; fire extinguishers are "
    "metal whatever their colour; handrails are usually metal; corridor and school floors are "
    "usually ceramic tile; interior walls are usually plasterboard (drywall) unless exposed "
    "block or poured concrete is visible; ceilings are plasterboard or mineral-fibre tiles "
    "(answer plasterboard); windows are glass; office doors with visible grain may be wood."
)


class VlmError(RuntimeError):
    """The VLM server could not be reached or refused the request; the message says how to fix."""


class VlmSetupError(VlmError):
    """The VLM server cannot serve this run at all (API key refused, wrong URL, a model name it does
    not serve, too few images per prompt): no segment can succeed. One line naming the fix; it
    stops the run whatever ``on_error`` says."""


def _one_line(text: str, limit: int = 200) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[:limit] + "..."


class AnswerError(ValueError):
    """The VLM's answer is not valid JSON with a known material."""


@dataclasses.dataclass(frozen=True)
class VlmConfig:
    """Options of the ``vlm`` material backend.

    Attributes
    ----------
    base_url : str — OpenAI-compatible API root, e.g. ``http://127.0.0.1:8000/v1`` (vLLM) or
        ``http://127.0.0.1:23333/v1`` (LMDeploy); ``/chat/completions`` is appended.
    model : str — model name as the server knows it.
    api_key_env : str or None — name of the environment variable holding the API key (the key
        itself never goes into a config file); unset variable = no Authorization header.
    timeout_s : float [s] — per-request timeout (connect + read).
    max_retries : int — retries after the first attempt, for timeouts/connection errors/5xx/429.
    backoff_s, backoff_max_s : float [s] — retry k waits ``min(backoff_s * 2**k, backoff_max_s)``.
    max_concurrency : int — requests in flight at once (thread pool size).
    cache_path : str or None — SQLite answer cache; None disables caching.
    on_error : ``"raise"`` or ``"unknown"`` — what a server failure does after the retries.
    response_format : ``"json_schema"``, ``"json_object"`` or ``"none"``.
    send_context : bool — also send the outlined full image (needs 2 images per prompt).
    crop_max_side, context_max_side : int [px] — PNG sizes (InternVL tiles are 448 px).
    crop_margin : float — bounding-box margin as a fraction of its size.
    temperature, max_tokens : sampling options sent to the server.
    prompt_version : str — cache-key component; bump when changing the prompt.
    """

    base_url: str = "http://127.0.0.1:8000/v1"
    model: str = "OpenGVLab/InternVL2_5-8B"
    api_key_env: str | None = "SIM2RADAR_VLM_API_KEY"
    timeout_s: float = 60.0
    max_retries: int = 3
    backoff_s: float = 1.0
    backoff_max_s: float = 30.0
    max_concurrency: int = 4
    cache_path: str | None = None
    on_error: Literal["raise", "unknown"] = "raise"
    response_format: Literal["json_schema", "json_object", "none"] = "json_schema"
    send_context: bool = True
    crop_max_side: int = 448
    context_max_side: int = 448
    crop_margin: float = 0.1
    temperature: float = 0.0
    max_tokens: int = 256
    prompt_version: str = PROMPT_VERSION

    def __post_init__(self) -> None:
        if not re.match(r"^https?://", self.base_url):
            raise ValueError(f"vlm: base_url must start with http:// or https://, got "
                             f"{self.base_url!r}")
        if self.timeout_s <= 0:
            raise ValueError(f"vlm: timeout_s must be > 0, got {self.timeout_s}")
        if self.max_retries < 0:
            raise ValueError(f"vlm: max_retries must be >= 0, got {self.max_retries}")
        if self.max_concurrency < 1:
            raise ValueError(f"vlm: max_concurrency must be >= 1, got {self.max_concurrency}")
        if self.on_error not in ("raise", "unknown"):
            raise ValueError(f"vlm: on_error must be 'raise' or 'unknown', got {self.on_error!r}")
        if self.response_format not in ("json_schema", "json_object", "none"):
            raise ValueError("vlm: response_format must be json_schema, json_object or none")
        if self.crop_max_side < 16 or self.context_max_side < 16:
            raise ValueError("vlm: crop_max_side/context_max_side must be >= 16 px")

    @property
    def url(self) -> str:
        return self.base_url.rstrip("/") + "/chat/completions"

    @property
    def models_url(self) -> str:
        return self.base_url.rstrip("/") + "/models"


# ---------------------------------------------------------------------------------------------
# Prompt and answer validation
# ---------------------------------------------------------------------------------------------

ANSWER_SCHEMA = {
    "type": "object",
    "properties": {
        "material": {"type": "string", "enum": list(MATERIAL_CLASSES)},
        "confidence": {"type": "number", "minimum": 0, "maximum": 1},
        "reason": {"type": "string"},
    },
    "required": ["material", "confidence", "reason"],
    "additionalProperties": False,
}


def build_prompt(semantic_label: str, with_context: bool) -> str:
    """The user prompt for one segment (version :data:`PROMPT_VERSION`)."""
    what = (
        f'A segmentation model labelled this segment "{semantic_label}".'
        if semantic_label and semantic_label != "unknown"
        else "The segment has no semantic label; decide what it is first."
    )
    images = (
        "Image 1 is a crop of the segment (pixels outside it are dimmed). Image 2 is the whole "
        "scene with the segment outlined in red."
        if with_context
        else "The image is a crop of the segment (pixels outside it are dimmed)."
    )
    materials = ", ".join(m for m in MATERIAL_CLASSES)
    return (
        f"{images} {what}\n"
        f"Classify the main material of the outlined surface for a 77 GHz radar simulation. "
        f"Choose exactly one of: {materials}. Use unknown only if it cannot be inferred.\n"
        f"{_MATERIAL_HINTS}\n"
        'Answer with only a JSON object: {"material": "<one of the classes>", '
        '"confidence": <number between 0 and 1>, "reason": "<one short sentence>"}'
    )


def _normalise_material(name: str) -> str:
    return re.sub(r"[\s\-]+", "_", name.strip().lower())


def _extract_json_object(text: str) -> dict:
    s = text.strip()
    fence = re.search(r"```(?:json|JSON)?\s*(.*?)```", s, re.S)
    candidates = [fence.group(1)] if fence else []
    candidates.append(s)
    dec = json.JSONDecoder()
    for cand in candidates:
        try:
            obj = json.loads(cand)
            if isinstance(obj, dict):
                return obj
        except ValueError:
            pass
        for m in re.finditer(r"\{", cand):
            try:
                obj, _ = dec.raw_decode(cand, m.start())
            except ValueError:
                continue
            if isinstance(obj, dict) and "material" in obj:
                return obj
    raise AnswerError(f"no JSON object in the answer: {text[:120]!r}")


def parse_answer(text: str) -> MaterialLabel:
    """Validate a VLM answer; raise :class:`AnswerError` if it is unusable.

    Accepts the JSON object bare, inside ``` fences or inside prose. The material must be in
    ``MATERIAL_CLASSES`` after normalising case, spaces and hyphens (``"Ceramic tile"`` ->
    ``ceramic_tile``). A missing or non-numeric confidence becomes 0.5 (noted in the reason);
    numbers are clipped to [0, 1].
    """
    if not isinstance(text, str) or not text.strip():
        raise AnswerError("empty answer")
    obj = _extract_json_object(text)
    raw = obj.get("material")
    if not isinstance(raw, str):
        raise AnswerError(f"'material' missing or not a string in {obj!r}"[:200])
    material = _normalise_material(raw)
    if material not in MATERIAL_CLASSES:
        raise AnswerError(
            f"out-of-vocabulary material {raw!r}; expected one of {', '.join(MATERIAL_CLASSES)}"
        )
    reason = str(obj.get("reason", "")).strip()
    conf = obj.get("confidence")
    try:
        confidence = float(conf)
        if not np.isfinite(confidence):
            raise ValueError
    except (TypeError, ValueError):
        confidence = 0.5
        reason = (reason + " " if reason else "") + f"[confidence {conf!r} invalid, set to 0.5]"
    return MaterialLabel(material, float(np.clip(confidence, 0.0, 1.0)), reason)


# ---------------------------------------------------------------------------------------------
# Cache
# ---------------------------------------------------------------------------------------------


class AnswerCache:
    """SQLite cache of validated answers: key -> (material, confidence, reason). Thread-safe."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path).expanduser()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        try:
            self._db = sqlite3.connect(str(self.path), check_same_thread=False)
            self._db.execute(
                "CREATE TABLE IF NOT EXISTS answers (key TEXT PRIMARY KEY, material TEXT, "
                "confidence REAL, reason TEXT, model TEXT, prompt_version TEXT, created REAL)"
            )
            self._db.commit()
        except sqlite3.DatabaseError as exc:
            raise VlmError(f"vlm cache {self.path}: not a usable SQLite file ({exc}); delete it "
                           "or choose another cache_path") from None

    def get(self, key: str) -> MaterialLabel | None:
        with self._lock:
            row = self._db.execute(
                "SELECT material, confidence, reason FROM answers WHERE key = ?", (key,)
            ).fetchone()
        return MaterialLabel(row[0], float(row[1]), row[2]) if row else None

    def put(self, key: str, label: MaterialLabel, model: str, prompt_version: str) -> None:
        with self._lock:
            self._db.execute(
                "INSERT OR REPLACE INTO answers VALUES (?, ?, ?, ?, ?, ?, ?)",
                (key, label.material, label.confidence, label.reason, model, prompt_version,
                 time.time()),
            )
            self._db.commit()

    def __len__(self) -> int:
        with self._lock:
            return int(self._db.execute("SELECT COUNT(*) FROM answers").fetchone()[0])

    def close(self) -> None:
        with self._lock:
            self._db.close()


# ---------------------------------------------------------------------------------------------
# HTTP client
# ---------------------------------------------------------------------------------------------


class _Retryable(Exception):
    pass


class ChatClient:
    """Minimal OpenAI-compatible chat-completions client (stdlib only) with retries.

    ``stats`` counts ``requests`` (HTTP attempts), ``retries`` and ``errors``.
    """

    def __init__(self, config: VlmConfig) -> None:
        self.config = config
        self._lock = threading.Lock()
        self.stats = {"requests": 0, "retries": 0, "errors": 0}
        self._response_format_ok = config.response_format != "none"

    def _count(self, key: str) -> None:
        with self._lock:
            self.stats[key] += 1

    def _headers(self) -> dict:
        h = {"Content-Type": "application/json", "Accept": "application/json"}
        env = self.config.api_key_env
        if env and os.environ.get(env):
            h["Authorization"] = f"Bearer {os.environ[env]}"
        return h

    def _payload(self, messages: list, with_rf: bool) -> dict:
        c = self.config
        body = {"model": c.model, "messages": messages, "temperature": c.temperature,
                "max_tokens": c.max_tokens}
        if with_rf:
            if c.response_format == "json_schema":
                body["response_format"] = {
                    "type": "json_schema",
                    "json_schema": {"name": "material_label", "schema": ANSWER_SCHEMA,
                                    "strict": True},
                }
            elif c.response_format == "json_object":
                body["response_format"] = {"type": "json_object"}
        return body

    def _post_once(self, body: dict) -> str:
        c = self.config
        req = urllib.request.Request(
            c.url, data=json.dumps(body).encode(), headers=self._headers(), method="POST"
        )
        self._count("requests")
        try:
            with urllib.request.urlopen(req, timeout=c.timeout_s) as resp:
                raw = resp.read()
        except urllib.error.HTTPError as exc:
            detail = _one_line(exc.read()[:600].decode("utf-8", "replace") if exc.fp else "")
            if exc.code >= 500 or exc.code == 429:
                raise _Retryable(f"HTTP {exc.code} from {c.url}: {detail}") from None
            if exc.code in (401, 403):
                raise VlmSetupError(self._auth_message(exc.code, c.url)) from None
            if exc.code == 404:
                raise VlmSetupError(
                    f"the VLM server at {c.base_url} answered HTTP 404 for {c.url} ({detail}): "
                    "set materials.options.base_url to its API root (ending in /v1) and "
                    f"materials.options.model ({c.model!r}) to a name it serves (GET "
                    f"{c.models_url} lists them)"
                ) from None
            if exc.code == 400 and re.search(r"at most \d+ image|limit.mm.per.prompt", detail,
                                             re.I):
                raise VlmSetupError(
                    f"the VLM server at {c.base_url} accepts fewer images per prompt than this "
                    f"backend sends (HTTP 400: {detail}): start vLLM with --limit-mm-per-prompt "
                    "'{\"image\": 2}', or set materials.options.send_context: false (one image)"
                ) from None
            raise VlmError(
                f"VLM server {c.url} refused the request with HTTP {exc.code}: {detail}; check "
                f"base_url, model ({c.model!r}) and the API key variable {c.api_key_env!r}"
            ) from None
        except urllib.error.URLError as exc:
            raise _Retryable(f"cannot reach {c.url}: {exc.reason}") from None
        except TimeoutError as exc:
            raise _Retryable(f"timeout after {c.timeout_s} s from {c.url}: {exc}") from None
        except (ConnectionError, http.client.HTTPException) as exc:
            raise _Retryable(f"connection error with {c.url}: {exc!r}") from None
        try:
            doc = json.loads(raw)
            content = doc["choices"][0]["message"]["content"]
        except (ValueError, KeyError, IndexError, TypeError):
            raise AnswerError(
                f"response is not a chat completion: {raw[:200]!r}"
            ) from None
        if isinstance(content, list):  # some servers return content parts
            content = "".join(p.get("text", "") for p in content if isinstance(p, dict))
        return content if isinstance(content, str) else ""

    def _auth_message(self, code: int, url: str) -> str:
        c = self.config
        sent = bool(c.api_key_env and os.environ.get(c.api_key_env))
        if sent:
            fix = (f"set ${c.api_key_env} to the key the server was started with (vLLM "
                   "--api-key, LMDeploy --api-keys)")
            return f"the VLM server at {c.base_url} refused the API key in ${c.api_key_env} " \
                   f"(HTTP {code} from {url}): {fix}"
        where = (f"export {c.api_key_env}=<the key the server was started with (vLLM "
                 "--api-key, LMDeploy --api-keys)>"
                 if c.api_key_env else
                 "set materials.options.api_key_env to the variable that holds the key")
        return (f"the VLM server at {c.base_url} wants an API key and none was sent (HTTP {code} "
                f"from {url}): {where}")

    def list_models(self) -> list[str] | None:
        """The model names the server serves (``GET {base_url}/models``, OpenAI's model list).

        Returns None when the server does not list them (HTTP 404 or another 4xx, or an answer
        that is not a model list). Raises :class:`VlmSetupError` on HTTP 401/403 and
        :class:`VlmError` when the server cannot be reached or answers 5xx/429.
        """
        c = self.config
        req = urllib.request.Request(c.models_url, headers=self._headers(), method="GET")
        try:
            with urllib.request.urlopen(req, timeout=min(c.timeout_s, 30.0)) as resp:
                raw = resp.read()
        except urllib.error.HTTPError as exc:
            if exc.code in (401, 403):
                raise VlmSetupError(self._auth_message(exc.code, c.models_url)) from None
            if exc.code >= 500 or exc.code == 429:
                raise VlmError(f"HTTP {exc.code} from {c.models_url}") from None
            return None
        except (urllib.error.URLError, TimeoutError, ConnectionError,
                http.client.HTTPException) as exc:
            reason = getattr(exc, "reason", exc)
            raise VlmError(
                f"cannot reach the VLM server at {c.base_url} ({reason}): is it running? (vLLM: "
                "`vllm serve <model>`; LMDeploy: `lmdeploy serve api_server <model>`)"
            ) from None
        try:
            return [str(m["id"]) for m in json.loads(raw)["data"]]
        except (ValueError, KeyError, TypeError):
            return None

    def complete(self, messages: list) -> str:
        """POST one chat completion and return the assistant's text.

        Raises :class:`VlmError` after ``max_retries`` retries or on a non-retryable HTTP error.
        """
        c = self.config
        attempt = 0
        while True:
            with_rf = self._response_format_ok
            try:
                return self._post_once(self._payload(messages, with_rf))
            except VlmSetupError:
                self._count("errors")
                raise
            except VlmError as exc:
                if with_rf and "HTTP 400" in str(exc):
                    log.warning("vlm: server rejected response_format; retrying without it")
                    self._response_format_ok = False
                    continue
                self._count("errors")
                raise
            except _Retryable as exc:
                if attempt >= c.max_retries:
                    self._count("errors")
                    raise VlmError(
                        f"VLM request failed after {attempt + 1} attempts: {exc}. Is the server "
                        f"running at {c.base_url}? (vLLM: `vllm serve <model>`; LMDeploy: "
                        "`lmdeploy serve api_server <model>`); or set on_error: unknown"
                    ) from None
                wait = min(c.backoff_s * 2**attempt, c.backoff_max_s)
                log.info("vlm: %s; retry %d/%d in %.2f s", exc, attempt + 1, c.max_retries, wait)
                self._count("retries")
                attempt += 1
                time.sleep(wait)


# ---------------------------------------------------------------------------------------------
# Images
# ---------------------------------------------------------------------------------------------


def _png(rgb: np.ndarray) -> bytes:
    import cv2

    ok, buf = cv2.imencode(".png", np.ascontiguousarray(rgb[..., ::-1]))
    if not ok:  # pragma: no cover
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def _fit(img: np.ndarray, max_side: int) -> np.ndarray:
    import cv2

    h, w = img.shape[:2]
    f = max_side / max(h, w)
    if f >= 1:
        return img
    return cv2.resize(img, (max(1, round(w * f)), max(1, round(h * f))),
                      interpolation=cv2.INTER_AREA)


def segment_images(
    rgb: np.ndarray, mask: np.ndarray, config: VlmConfig
) -> tuple[bytes, bytes | None]:
    """PNG bytes of the segment crop (outside dimmed) and of the outlined, downscaled context."""
    import cv2

    rows, cols = np.nonzero(mask)
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    mr = int(round(config.crop_margin * (r1 - r0))) + 1
    mc = int(round(config.crop_margin * (c1 - c0))) + 1
    r0, r1 = max(0, r0 - mr), min(rgb.shape[0], r1 + mr)
    c0, c1 = max(0, c0 - mc), min(rgb.shape[1], c1 + mc)
    crop = rgb[r0:r1, c0:c1].astype(np.float32)
    m = mask[r0:r1, c0:c1, None]
    crop = np.where(m, crop, 0.35 * crop).astype(np.uint8)
    crop_png = _png(_fit(crop, config.crop_max_side))
    if not config.send_context:
        return crop_png, None
    ctx = np.ascontiguousarray(rgb.copy())
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_SIMPLE)
    thick = max(1, round(max(rgb.shape[:2]) / 200))
    cv2.drawContours(ctx, contours, -1, (255, 0, 0), thick)
    return crop_png, _png(_fit(ctx, config.context_max_side))


def _data_url(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


# ---------------------------------------------------------------------------------------------
# Backend
# ---------------------------------------------------------------------------------------------


@MATERIAL_BACKENDS.register("vlm")
class VlmMaterials:
    """Stage 3 backend ``vlm``: one chat-completion per segment (see the module docstring).

    Options are the fields of :class:`VlmConfig`. After :meth:`label`, ``self.stats`` holds
    ``requests``, ``retries``, ``errors``, ``cache_hits``, ``fallbacks``.
    """

    def __init__(self, **options) -> None:
        try:
            self.config = VlmConfig(**options)
        except TypeError as exc:
            known = ", ".join(f.name for f in dataclasses.fields(VlmConfig))
            raise ValueError(f"vlm material backend: {exc}; known options: {known}") from None
        self.client = ChatClient(self.config)
        self.cache = AnswerCache(self.config.cache_path) if self.config.cache_path else None
        self.stats = {"cache_hits": 0, "fallbacks": 0}
        self._stats_lock = threading.Lock()
        self._abort = threading.Event()
        self._server_checked = False
        self._setup_error: VlmSetupError | None = None

    def check(self) -> str:
        """Ask the server which models it serves (``GET {base_url}/models``) and compare.

        Returns a one-line description. Raises :class:`VlmSetupError` when the key is refused or
        ``model`` is not among the served names (the message lists them), :class:`VlmError` when
        the server cannot be reached.
        """
        c = self.config
        served = self.client.list_models()
        if served is None:
            return (f"the server at {c.base_url} answers but does not list its models "
                    f"(GET {c.models_url}); model name {c.model!r} not verified")
        if c.model not in served:
            raise VlmSetupError(
                f"the server at {c.base_url} serves {served}, not {c.model!r}: set "
                "materials.options.model to one of them, or start vLLM with "
                f"--served-model-name {c.model} (LMDeploy: --model-name {c.model})"
            )
        return f"the server at {c.base_url} serves {c.model!r}"

    def _check_server_once(self) -> None:
        """Before the first request: :meth:`check`, once per backend. A refused key or an unknown
        model name is remembered and raised for every later frame too; an unreachable server is
        left to the requests (their retries and ``on_error``) and asked again next frame."""
        if self._setup_error is not None:
            raise VlmSetupError(str(self._setup_error))
        if self._server_checked:
            return
        try:
            log.info("vlm: %s", self.check())
        except VlmSetupError as exc:
            self._setup_error = exc
            raise
        except VlmError as exc:
            log.info("vlm: model list not checked: %s", exc)
            return
        self._server_checked = True

    def _fallback(self) -> None:
        with self._stats_lock:
            self.stats["fallbacks"] += 1

    def _key(self, crop: bytes, ctx: bytes | None, label: str) -> str:
        h = hashlib.sha256()
        for part in (crop, ctx or b"", label.encode(), self.config.model.encode(),
                     self.config.prompt_version.encode()):
            h.update(hashlib.sha256(part).digest())
        return h.hexdigest()

    def _messages(self, crop: bytes, ctx: bytes | None, label: str) -> list:
        content = [{"type": "text", "text": build_prompt(label, ctx is not None)},
                   {"type": "image_url", "image_url": {"url": _data_url(crop)}}]
        if ctx is not None:
            content.append({"type": "image_url", "image_url": {"url": _data_url(ctx)}})
        return [
            {"role": "system", "content": "You are an expert in building materials and their "
             "radar (mmWave) properties. You answer with JSON only."},
            {"role": "user", "content": content},
        ]

    def _ask(self, name: str, index: int, crop: bytes, ctx: bytes | None, label: str,
             key: str) -> MaterialLabel:
        if self._abort.is_set():  # another segment already failed with on_error: raise
            raise VlmError(f"{name}: segment {index}: skipped after an earlier VLM failure")
        try:
            text = self.client.complete(self._messages(crop, ctx, label))
        except VlmSetupError as exc:  # whatever on_error says: no segment can succeed
            if self._setup_error is None:
                self._setup_error = exc
            self._abort.set()
            raise
        except VlmError as exc:
            if self.config.on_error == "raise":
                self._abort.set()
                raise VlmError(f"{name}: segment {index}: {exc}") from None
            self._fallback()
            log.warning("%s: segment %d: VLM failed, labelled unknown: %s", name, index, exc)
            return MaterialLabel("unknown", 0.0, f"VLM request failed: {exc}", fallback=True)
        except AnswerError as exc:
            self._fallback()
            log.warning("%s: segment %d: unusable VLM response: %s", name, index, exc)
            return MaterialLabel("unknown", 0.0, f"invalid VLM response: {exc}", fallback=True)
        try:
            answer = parse_answer(text)
        except AnswerError as exc:
            self._fallback()
            log.warning("%s: segment %d: VLM answer rejected, labelled unknown: %s",
                        name, index, exc)
            return MaterialLabel("unknown", 0.0, f"invalid VLM answer: {exc}", fallback=True)
        if self.cache is not None:
            self.cache.put(key, answer, self.config.model, self.config.prompt_version)
        return answer

    def label(
        self, frame: FrameInput, depth: DepthResult, segments: Segments
    ) -> list[MaterialLabel]:
        seg = np.asarray(segments.segment_id)
        if seg.shape != frame.shape:
            raise ValueError(
                f"{frame.name}: segment_id is {seg.shape} but the image is {frame.shape}"
            )
        n = segments.n_segments
        results: list[MaterialLabel | None] = [None] * n
        jobs = []
        for i in range(n):
            mask = seg == i
            if not mask.any():
                results[i] = MaterialLabel("unknown", 0.0, "segment has no pixels")
                continue
            label = segments.labels[i]
            crop, ctx = segment_images(frame.rgb, mask, self.config)
            key = self._key(crop, ctx, label)
            hit = self.cache.get(key) if self.cache is not None else None
            if hit is not None:
                self.stats["cache_hits"] += 1
                results[i] = hit
            else:
                jobs.append((i, crop, ctx, label, key))
        if jobs:
            self._check_server_once()
            self._abort.clear()
            with ThreadPoolExecutor(max_workers=self.config.max_concurrency,
                                    thread_name_prefix="vlm") as pool:
                futures = {
                    i: pool.submit(self._ask, frame.name, i, crop, ctx, label, key)
                    for i, crop, ctx, label, key in jobs
                }
                try:
                    for i, fut in futures.items():
                        results[i] = fut.result()
                except BaseException:
                    for fut in futures.values():
                        fut.cancel()
                    if self._setup_error is not None:  # the cause, not a skipped segment's echo
                        raise VlmSetupError(str(self._setup_error)) from None
                    raise
        self.stats.update(self.client.stats)
        return [r for r in results if r is not None]
