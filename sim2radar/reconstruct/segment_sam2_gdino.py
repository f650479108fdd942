"""Stage 2 ``sam2-gdino`` backend: SAM2 automatic masks + Grounding DINO labels (paper §3 Stage 2).

SAM2 (Ravi et al. 2024) segments the image into regions; Grounding DINO (Liu et al. 2023) detects
the prompt's classes ("door, wall, floor, ceiling, window, fire extinguisher, handrail"); each SAM2
mask takes the label of the detection box with the highest mask-to-box IoU (paper §3 Stage 2).
Both models run from user-supplied ONNX exports through onnxruntime; names are configurable.

SAM2 — the common export split (e.g. ``samexporter``, 1024×1024 input):

* encoder ``image`` (1, 3, S, S) float32, RGB resized (not letter-boxed) to S×S, ImageNet
  mean/std normalised -> ``image_embed`` (1, 256, S/16, S/16), ``high_res_feats_0``
  (1, 32, S/4, S/4), ``high_res_feats_1`` (1, 64, S/8, S/8).
* decoder ``image_embed``, ``high_res_feats_0``, ``high_res_feats_1``, ``point_coords``
  (B, P, 2) float32 in the S×S input frame [px], ``point_labels`` (B, P) float32 (1 = foreground,
  -1 = padding), ``mask_input`` (B, 1, S/4, S/4), ``has_mask_input`` (1,) and optionally
  ``orig_im_size`` (2,) [H, W] -> ``masks`` (B, M, h, w) logits (any h, w; resized to the image)
  and ``iou_predictions`` (B, M).

onnxruntime's own SAM2 exporter (``onnxruntime/python/tools/transformers/models/sam2``) names
them differently and writes ``masks`` already resized and thresholded (boolean), which a decoder
output of boolean type is refused for; its logits are ``low_res_masks``. Its mapping::

    encoder_outputs: [image_features_0, image_features_1, image_embeddings]
    decoder_inputs: [point_coords, point_labels, input_masks, has_input_masks,
                     original_image_size]
    decoder_outputs: [low_res_masks, iou_predictions]

Automatic mask generation (SAM's ``SamAutomaticMaskGenerator`` without crops): a regular
``points_per_side``² grid of single foreground points; all M multimask outputs are candidates;
keep those with predicted IoU ≥ ``pred_iou_thresh`` and stability score (IoU of the masks
thresholded at ±``stability_offset`` around the mask threshold, SAM's ``calculate_stability_score``)
≥ ``stability_score_thresh``; greedy mask-IoU NMS at ``nms_iou``; then the masks are painted
largest first, so smaller objects (a fire extinguisher on a wall) stay on top; segments smaller
than ``min_area_px`` after painting are dropped.

Grounding DINO — the common ONNX export (e.g. X-AnyLabeling's ``export_grounding_dino_onnx``):

* inputs ``img`` (1, 3, H, W) float32 (ImageNet-normalised RGB, plainly resized — not
  letter-boxed — to ``input_hw``), ``input_ids`` (1, T),
  ``attention_mask`` (1, T), ``position_ids`` (1, T), ``token_type_ids`` (1, T),
  ``text_token_mask`` (1, T, T) — the integer/bool dtypes are read from the graph;
* outputs ``logits`` (1, Q, 256) token-alignment logits, ``boxes`` (1, Q, 4) normalised
  (cx, cy, w, h). A plain resize keeps normalised coordinates, so a box maps back to the frame as
  ``(cx · W0, cy · H0, w · W0, h · H0)`` whatever ``input_hw`` is.

Input size: public exports declare H and W dynamic, but the Swin backbone's window partition and
attention mask are traced with the export's constant shapes, so the graph runs only at the size it
was exported at (X-AnyLabeling's script traces 1×3×800×1200; 800×1067, 750×1333 and 800×800 fail
with an onnxruntime Reshape error). ``input_hw`` therefore defaults to the graph's fixed H, W when
it declares them, else to :data:`GDINO_EXPORT_HW`; a Reshape/shape failure at run time raises
:class:`ModelSignatureError` naming the option.

Tokenisation: no tokenizer is downloaded. The user supplies the BERT-base-uncased vocabulary that
belongs to their Grounding DINO weights — either ``vocab.txt`` (one WordPiece token per line,
id = line number) or HuggingFace ``tokenizer.json`` (its ``model.vocab`` map) — and
:class:`WordPieceTokenizer` reproduces BERT's uncased basic + WordPiece tokenisation for the
prompt (lower case, split at whitespace and punctuation, greedy longest-match WordPieces with
``##`` continuations). The caption is the prompt in Grounding DINO's form
``"door . wall . floor . ... ."``; the sub-sentence attention mask and position ids follow
Grounding DINO's ``generate_masks_with_special_tokens_and_transfer_map`` ([CLS], [SEP], "." and
"?" delimit phrases). A query's score for a class is the max sigmoid logit over that class's
tokens; a query is a detection of its best class if that score ≥ ``box_threshold``; per-class box
NMS at ``nms_iou``.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import re
import unicodedata
from pathlib import Path

import numpy as np

from sim2radar.reconstruct._onnx import ModelSignatureError, OnnxModel, onnx_dtype
from sim2radar.reconstruct.types import (
    SEGMENT_BACKENDS,
    DepthResult,
    FrameInput,
    ReconstructionInputError,
    Segments,
)
from sim2radar.vocab import DETECTION_PROMPT, SEMANTIC_CLASSES

__all__ = [
    "GDINO_EXPORT_HW",
    "Detections",
    "GroundingDino",
    "GroundingDinoConfig",
    "Sam2AutoMasks",
    "Sam2Config",
    "Sam2GdinoSegments",
    "WordPieceTokenizer",
    "match_masks_to_detections",
    "text_masks",
]

log = logging.getLogger(__name__)

_IMAGENET_MEAN = np.array([0.485, 0.456, 0.406], np.float32)
_IMAGENET_STD = np.array([0.229, 0.224, 0.225], np.float32)

#: (H, W) [px] a Grounding DINO graph with symbolic H, W is fed by default: the size public exports
#: are traced at and the only one their Swin backbone runs at (X-AnyLabeling's
#: ``export_grounding_dino_onnx.py``: ``img = torch.randn(1, 3, 800, 1200)``).
GDINO_EXPORT_HW = (800, 1200)


def _normalise(rgb: np.ndarray, size_hw: tuple[int, int]) -> np.ndarray:
    """(1, 3, h, w) float32: resized RGB / 255, ImageNet mean/std normalised."""
    import cv2

    h, w = size_hw
    img = cv2.resize(rgb, (w, h), interpolation=cv2.INTER_LINEAR) if rgb.shape[:2] != (h, w) \
        else rgb
    x = (img.astype(np.float32) / 255.0 - _IMAGENET_MEAN) / _IMAGENET_STD
    return np.ascontiguousarray(x.transpose(2, 0, 1)[None])


def _options(cls, options: dict | None, what: str):
    try:
        return cls(**(options or {}))
    except TypeError as exc:
        known = ", ".join(f.name for f in dataclasses.fields(cls))
        raise ValueError(f"{what}: {exc}; known options: {known}") from None


# ---------------------------------------------------------------------------------------------
# Tokeniser
# ---------------------------------------------------------------------------------------------


class WordPieceTokenizer:
    """BERT uncased basic + WordPiece tokenizer over a user-supplied vocabulary.

    Parameters
    ----------
    vocab : path to ``vocab.txt`` / ``tokenizer.json``, or a ``{token: id}`` mapping.
    """

    def __init__(self, vocab: str | Path | dict[str, int]) -> None:
        if isinstance(vocab, dict):
            self.vocab = {str(k): int(v) for k, v in vocab.items()}
        else:
            path = Path(vocab).expanduser()
            if not path.is_file():
                raise FileNotFoundError(
                    f"Grounding DINO vocabulary {path} not found; supply the vocab.txt or "
                    "tokenizer.json of bert-base-uncased that came with your weights"
                )
            if path.suffix == ".json":
                doc = json.loads(path.read_text())
                table = doc.get("model", {}).get("vocab", doc) if isinstance(doc, dict) else None
                if not isinstance(table, dict):
                    raise ValueError(f"{path}: expected tokenizer.json with model.vocab or a "
                                     "{token: id} object")
                self.vocab = {str(k): int(v) for k, v in table.items()}
            else:
                lines = path.read_text(encoding="utf-8").splitlines()
                self.vocab = {tok.strip(): i for i, tok in enumerate(lines) if tok.strip()}
        for special in ("[CLS]", "[SEP]", "[UNK]", "."):
            if special not in self.vocab:
                raise ValueError(f"Grounding DINO vocabulary lacks the token {special!r}; is it "
                                 "a BERT (uncased) vocabulary?")

    def id(self, token: str) -> int:
        return self.vocab.get(token, self.vocab["[UNK]"])

    @staticmethod
    def basic_tokens(text: str) -> list[str]:
        """Lower-case, strip accents, split at whitespace and punctuation (BERT BasicTokenizer)."""
        text = unicodedata.normalize("NFD", text.lower())
        text = "".join(c for c in text if unicodedata.category(c) != "Mn")
        out = []
        for word in text.split():
            out.extend(t for t in re.split(r"([^\w]|_)", word) if t)
        return out

    def wordpieces(self, word: str, max_chars: int = 100) -> list[str]:
        """Greedy longest-match-first WordPiece split of one basic token."""
        if len(word) > max_chars:
            return ["[UNK]"]
        pieces, start = [], 0
        while start < len(word):
            end, cur = len(word), None
            while start < end:
                sub = word[start:end] if start == 0 else "##" + word[start:end]
                if sub in self.vocab:
                    cur = sub
                    break
                end -= 1
            if cur is None:
                return ["[UNK]"]
            pieces.append(cur)
            start = end
        return pieces

    def encode_phrases(self, phrases: list[str]) -> tuple[np.ndarray, list[list[int]]]:
        """Token ids of ``"[CLS] p1 . p2 . ... pn . [SEP]"`` and the token positions of each phrase."""
        ids = [self.vocab["[CLS]"]]
        spans: list[list[int]] = []
        for phrase in phrases:
            span = []
            for word in self.basic_tokens(phrase):
                for piece in self.wordpieces(word):
                    span.append(len(ids))
                    ids.append(self.id(piece))
            spans.append(span)
            ids.append(self.vocab["."])
        ids.append(self.vocab["[SEP]"])
        return np.asarray(ids, np.int64), spans

    def special_ids(self) -> list[int]:
        return [self.vocab[t] for t in ("[CLS]", "[SEP]", ".", "?") if t in self.vocab]


def text_masks(input_ids: np.ndarray, special_ids: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Sub-sentence self-attention mask (T, T) bool and position ids (T,) int64.

    NumPy port of Grounding DINO's ``generate_masks_with_special_tokens_and_transfer_map``: tokens
    attend only within their phrase; position ids restart at 0 after every special token.
    """
    ids = np.asarray(input_ids).reshape(-1)
    t = ids.size
    special = np.isin(ids, special_ids)
    att = np.eye(t, dtype=bool)
    pos = np.zeros(t, np.int64)
    prev = 0
    for col in np.flatnonzero(special):
        if col == 0 or col == t - 1:
            att[col, col] = True
            pos[col] = 0
        else:
            att[prev + 1:col + 1, prev + 1:col + 1] = True
            pos[prev + 1:col + 1] = np.arange(0, col - prev)
        prev = col
    return att, pos


# ---------------------------------------------------------------------------------------------
# Grounding DINO
# ---------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Detections:
    """Boxes (N, 4) float32 x0, y0, x1, y1 [px of the frame], labels (N,) semantic names,
    scores (N,) float32."""

    boxes: np.ndarray
    labels: tuple[str, ...]
    scores: np.ndarray

    def __len__(self) -> int:
        return len(self.labels)


@dataclasses.dataclass(frozen=True)
class GroundingDinoConfig:
    """Options of the Grounding DINO half (``gdino:`` in the backend options).

    model_path : the ``.onnx``; vocab_path : ``vocab.txt`` or ``tokenizer.json`` (BERT uncased).
    prompt : comma-separated class phrases (default: the paper's prompt). Each phrase maps to the
        semantic class with spaces -> underscores ("fire extinguisher" -> fire_extinguisher).
    box_threshold : minimum class score of a detection; nms_iou : per-class box NMS.
    input_hw : (H, W) [px] the image is plainly resized to before the graph (None: the graph's
        fixed H, W, or :data:`GDINO_EXPORT_HW` when they are symbolic — see the module docstring).
    max_text_len : the model's logits width (256 for the public weights).
    input_names : (img, input_ids, attention_mask, position_ids, token_type_ids, text_token_mask);
    output_names : (logits, boxes).
    """

    model_path: str
    vocab_path: str
    prompt: str = DETECTION_PROMPT
    box_threshold: float = 0.35
    nms_iou: float = 0.5
    input_hw: tuple[int, int] | None = None
    max_text_len: int = 256
    input_names: tuple[str, ...] = ("img", "input_ids", "attention_mask", "position_ids",
                                    "token_type_ids", "text_token_mask")
    output_names: tuple[str, ...] = ("logits", "boxes")
    providers: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "input_names", tuple(self.input_names))
        object.__setattr__(self, "output_names", tuple(self.output_names))
        if len(self.input_names) != 6 or len(self.output_names) != 2:
            raise ValueError("gdino: input_names needs 6 names and output_names 2")
        if not 0 < self.box_threshold < 1:
            raise ValueError(f"gdino: box_threshold must lie in (0, 1), got {self.box_threshold}")
        if self.input_hw is not None:
            hw = tuple(self.input_hw)
            if len(hw) != 2 or not all(isinstance(v, int) and v >= 32 for v in hw):
                raise ValueError(f"gdino: input_hw must be [H, W], two integers >= 32 px, got "
                                 f"{self.input_hw!r}")
            object.__setattr__(self, "input_hw", hw)


def _box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU matrix (N, M) of x0y0x1y1 boxes."""
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.prod(np.clip(rb - lt, 0, None), axis=-1)
    area_a = np.prod(np.clip(a[:, 2:] - a[:, :2], 0, None), axis=-1)
    area_b = np.prod(np.clip(b[:, 2:] - b[:, :2], 0, None), axis=-1)
    return inter / np.maximum(area_a[:, None] + area_b[None] - inter, 1e-12)


def _nms(boxes: np.ndarray, scores: np.ndarray, iou: float) -> list[int]:
    order = list(np.argsort(-scores, kind="stable"))
    keep: list[int] = []
    while order:
        i = order.pop(0)
        keep.append(i)
        if order:
            ious = _box_iou(boxes[i:i + 1], boxes[order])[0]
            order = [j for j, v in zip(order, ious, strict=True) if v < iou]
    return keep


class GroundingDino:
    """Grounding DINO via onnxruntime (see the module docstring for the signature)."""

    def __init__(self, config: GroundingDinoConfig) -> None:
        self.config = c = config
        self.tokenizer = WordPieceTokenizer(c.vocab_path)
        self.model = OnnxModel(c.model_path, "Grounding DINO (sam2-gdino option gdino.model_path)",
                               inputs=c.input_names[:2], optional_inputs=c.input_names[2:],
                               outputs=c.output_names, providers=c.providers)
        self.input_hw = self._input_hw()
        self.phrases = [p.strip() for p in c.prompt.split(",") if p.strip()]
        if not self.phrases:
            raise ValueError("gdino: empty prompt")
        self.classes = []
        for p in self.phrases:
            name = re.sub(r"\s+", "_", p.lower())
            if name not in SEMANTIC_CLASSES:
                raise ValueError(f"gdino: prompt phrase {p!r} is not a semantic class; known: "
                                 f"{SEMANTIC_CLASSES}")
            self.classes.append(name)
        self.input_ids, self.spans = self.tokenizer.encode_phrases(self.phrases)
        if len(self.input_ids) > c.max_text_len:
            raise ValueError(f"gdino: prompt is {len(self.input_ids)} tokens, max {c.max_text_len}")
        for p, span in zip(self.phrases, self.spans, strict=True):
            unk = [i for i in span if self.input_ids[i] == self.tokenizer.vocab["[UNK]"]]
            if unk:
                log.warning("gdino: phrase %r has tokens unknown to the vocabulary", p)

    def _input_hw(self) -> tuple[int, int]:
        """The (H, W) [px] the image is resized to: ``input_hw``, else the graph's fixed size,
        else :data:`GDINO_EXPORT_HW`; a fixed graph size that ``input_hw`` contradicts fails."""
        shape = self.model.input_shape(self.config.input_names[0])
        fixed = (len(shape) == 4 and isinstance(shape[2], int) and isinstance(shape[3], int)
                 and shape[2] > 0 and shape[3] > 0)
        want = self.config.input_hw
        if fixed and want is not None and tuple(want) != (shape[2], shape[3]):
            raise ModelSignatureError(
                f"Grounding DINO: {self.model.path.name} takes a fixed {shape[2]}x{shape[3]} "
                f"image, but gdino input_hw is {list(want)}; set input_hw to "
                f"[{shape[2]}, {shape[3]}] or leave it out"
            )
        if want is not None:
            return tuple(want)
        return (int(shape[2]), int(shape[3])) if fixed else GDINO_EXPORT_HW

    def _run(self, feeds: dict) -> dict:
        try:
            return self.model.run(feeds, self.config.output_names)
        except ModelSignatureError as exc:
            said = " ".join(str(exc).split("}: ", 1)[-1].split())  # onnxruntime's own text
            if not re.search(r"reshape|shape", said, re.I):
                raise
            h, w = self.input_hw
            node = re.search(r"running (\w+) node", said)
            said = (f"{node.group(1)} node: " if node else "") + (
                said if len(said) <= 160 else "..." + said[-160:])
            raise ModelSignatureError(
                f"Grounding DINO: {self.model.path.name} does not run at {h}x{w}: a Swin-backbone "
                "export fixes its attention-window shapes at the size it was traced at, even when "
                "it declares dynamic H, W (X-AnyLabeling's export: 800x1200); set the sam2-gdino "
                "option gdino_input_hw (gdino: {input_hw: [H, W]}) to that size "
                f"(onnxruntime: {said})"
            ) from None

    def detect(self, rgb: np.ndarray) -> Detections:
        c = self.config
        h0, w0 = rgb.shape[:2]
        img = _normalise(rgb, self.input_hw)
        ids = self.input_ids[None]
        att, pos = text_masks(ids, self.tokenizer.special_ids())
        names = c.input_names
        values = {
            names[0]: img,
            names[1]: ids,
            names[2]: np.ones_like(ids),
            names[3]: pos[None],
            names[4]: np.zeros_like(ids),
            names[5]: att[None],
        }
        feeds = {}
        for n, v in values.items():
            if self.model.has_input(n):
                feeds[n] = v.astype(onnx_dtype(self.model.input_type(n)))
        out = self._run(feeds)
        logits = np.asarray(out[c.output_names[0]], np.float32)[0]  # (Q, L)
        boxes = np.asarray(out[c.output_names[1]], np.float32)[0]  # (Q, 4)
        if logits.ndim != 2 or boxes.shape != (logits.shape[0], 4):
            raise ReconstructionInputError(
                f"Grounding DINO outputs have shapes {logits.shape}, {boxes.shape}; expected "
                "(1, Q, L) logits and (1, Q, 4) boxes"
            )
        prob = 1.0 / (1.0 + np.exp(-logits))
        per_class = np.stack(
            [prob[:, span].max(axis=1) if span else np.zeros(len(prob)) for span in self.spans],
            axis=1,
        )  # (Q, n_classes)
        best = per_class.argmax(axis=1)
        score = per_class[np.arange(len(best)), best]
        keep = score >= c.box_threshold
        cx, cy, bw, bh = boxes[keep].T  # normalised: a plain resize maps them back unchanged
        xyxy = np.stack([(cx - bw / 2) * w0, (cy - bh / 2) * h0, (cx + bw / 2) * w0,
                         (cy + bh / 2) * h0], axis=1).astype(np.float32)
        xyxy = np.clip(xyxy, 0, [w0, h0, w0, h0]).astype(np.float32)
        cls = best[keep]
        sc = score[keep].astype(np.float32)
        final = []
        for k in np.unique(cls):
            idx = np.flatnonzero(cls == k)
            final.extend(idx[j] for j in _nms(xyxy[idx], sc[idx], c.nms_iou))
        final = sorted(final, key=lambda i: -sc[i])
        return Detections(xyxy[final].reshape(-1, 4), tuple(self.classes[cls[i]] for i in final),
                          sc[final])


# ---------------------------------------------------------------------------------------------
# SAM2 automatic masks
# ---------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Sam2Config:
    """Options of the SAM2 half (``sam2:`` in the backend options); see the module docstring."""

    encoder_path: str
    decoder_path: str
    input_size: int = 1024
    points_per_side: int = 32
    points_per_batch: int = 64
    pred_iou_thresh: float = 0.8
    stability_score_thresh: float = 0.92
    stability_offset: float = 1.0
    mask_threshold: float = 0.0
    nms_iou: float = 0.7
    min_area_px: int = 25
    nms_max_side: int = 128
    pad_point: bool = False
    encoder_input: str = "image"
    encoder_outputs: tuple[str, ...] = ("image_embed", "high_res_feats_0", "high_res_feats_1")
    decoder_inputs: tuple[str, ...] = ("point_coords", "point_labels", "mask_input",
                                       "has_mask_input", "orig_im_size")
    decoder_outputs: tuple[str, ...] = ("masks", "iou_predictions")
    providers: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        for name in ("encoder_outputs", "decoder_inputs", "decoder_outputs"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        if len(self.decoder_inputs) != 5 or len(self.decoder_outputs) != 2:
            raise ValueError("sam2: decoder_inputs needs 5 names and decoder_outputs 2")
        if self.points_per_side < 1 or self.points_per_batch < 1:
            raise ValueError("sam2: points_per_side and points_per_batch must be >= 1")


class Sam2AutoMasks:
    """SAM2 automatic mask generation over onnxruntime (see the module docstring)."""

    def __init__(self, config: Sam2Config) -> None:
        self.config = c = config
        self.encoder = OnnxModel(c.encoder_path, "SAM2 encoder (sam2-gdino option "
                                 "sam2.encoder_path)", inputs=[c.encoder_input],
                                 outputs=c.encoder_outputs, providers=c.providers)
        coords, labels, mask_in, has_mask, orig = c.decoder_inputs
        self.decoder = OnnxModel(c.decoder_path, "SAM2 decoder (sam2-gdino option "
                                 "sam2.decoder_path)",
                                 inputs=list(c.encoder_outputs) + [coords, labels],
                                 optional_inputs=[mask_in, has_mask, orig],
                                 outputs=c.decoder_outputs, providers=c.providers)
        if self.decoder.output_type(c.decoder_outputs[0]) == "tensor(bool)":
            raise ModelSignatureError(
                f"SAM2 decoder: {self.decoder.path.name}'s output {c.decoder_outputs[0]!r} is "
                "boolean (already thresholded, as onnxruntime's SAM2 exporter writes 'masks'), "
                "but the mask logits are needed; set sam2 decoder_outputs: [low_res_masks, "
                "iou_predictions] (see the README for its other names)"
            )
        shp = self.decoder.input_shape(coords)
        self.fixed_batch = shp[0] if shp and isinstance(shp[0], int) else None

    def _grid(self, h: int, w: int) -> np.ndarray:
        n = self.config.points_per_side
        g = (np.arange(n) + 0.5) / n
        xx, yy = np.meshgrid(g * w, g * h)
        return np.stack([xx.ravel(), yy.ravel()], 1)  # (N, 2) [px of the frame]

    def _decoder_feeds(self, emb: dict, pts_in: np.ndarray, h0: int, w0: int) -> dict:
        c = self.config
        coords_n, labels_n, mask_n, has_n, orig_n = c.decoder_inputs
        b = len(pts_in)
        coords = pts_in[:, None, :].astype(np.float32)
        labels = np.ones((b, 1), np.float32)
        if c.pad_point:
            coords = np.concatenate([coords, np.zeros((b, 1, 2), np.float32)], 1)
            labels = np.concatenate([labels, -np.ones((b, 1), np.float32)], 1)
        feeds = dict(emb)
        feeds[coords_n] = coords
        feeds[labels_n] = labels.astype(onnx_dtype(self.decoder.input_type(labels_n)))
        if self.decoder.has_input(mask_n):
            shp = self.decoder.input_shape(mask_n)
            mh = shp[2] if len(shp) == 4 and isinstance(shp[2], int) else c.input_size // 4
            mw = shp[3] if len(shp) == 4 and isinstance(shp[3], int) else c.input_size // 4
            mb = shp[0] if isinstance(shp[0], int) else b
            feeds[mask_n] = np.zeros((mb, 1, mh, mw), np.float32)
        if self.decoder.has_input(has_n):
            shp = self.decoder.input_shape(has_n)
            n = shp[0] if shp and isinstance(shp[0], int) else 1
            feeds[has_n] = np.zeros((n,), onnx_dtype(self.decoder.input_type(has_n)))
        if self.decoder.has_input(orig_n):
            feeds[orig_n] = np.array([h0, w0], onnx_dtype(self.decoder.input_type(orig_n)))
        return feeds

    def _encode(self, rgb: np.ndarray) -> dict[str, np.ndarray]:
        c = self.config
        s = c.input_size
        out = self.encoder.run({c.encoder_input: _normalise(rgb, (s, s))}, c.encoder_outputs)
        return {k: np.asarray(v) for k, v in out.items()}

    def _decode(self, emb: dict, pts_in: np.ndarray, h0: int, w0: int,
                n_real: int) -> tuple[np.ndarray, np.ndarray]:
        """Mask logits (n_real, M, h, w) float32 and predicted IoUs (n_real, M) of one batch of
        single-point prompts ``pts_in`` (B, 2) [px of the S×S input]."""
        c = self.config
        out = self.decoder.run(self._decoder_feeds(emb, pts_in, h0, w0), c.decoder_outputs)
        logits = np.asarray(out[c.decoder_outputs[0]], np.float32)[:n_real]
        ious = np.asarray(out[c.decoder_outputs[1]], np.float32)[:n_real]
        if logits.ndim != 4 or ious.shape != logits.shape[:2]:
            raise ReconstructionInputError(
                f"SAM2 decoder outputs have shapes {logits.shape}, {ious.shape}; expected "
                "(B, M, h, w) masks and (B, M) iou_predictions"
            )
        return logits, ious

    def probe(self, rgb: np.ndarray) -> str:
        """Run the encoder and one decoder batch (one point at the image centre) on ``rgb``;
        return a one-line summary of the decoder's outputs (``sim2radar models check``)."""
        h0, w0 = rgb.shape[:2]
        s = self.config.input_size
        n = self.fixed_batch or 1
        pts = np.repeat(np.array([[s / 2, s / 2]], np.float32), n, 0)
        logits, ious = self._decode(self._encode(rgb), pts, h0, w0, 1)
        return (f"SAM2 ({self.decoder.path.name}) masks {tuple(logits.shape[1:])}, logits in "
                f"[{logits.min():.1f}, {logits.max():.1f}], predicted IoU {float(ious.max()):.2f}")

    def generate(self, rgb: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
        """Automatic masks of an image.

        Returns
        -------
        masks : list of (H, W) bool, after filtering and NMS, best first.
        scores : (K,) float32 predicted IoU of each mask.
        """
        import cv2

        c = self.config
        h0, w0 = rgb.shape[:2]
        s = c.input_size
        emb = self._encode(rgb)
        grid = self._grid(h0, w0)
        grid_in = grid * np.array([s / w0, s / h0])
        batch = self.fixed_batch or c.points_per_batch
        f_nms = min(1.0, c.nms_max_side / max(h0, w0))
        nms_hw = (max(1, round(h0 * f_nms)), max(1, round(w0 * f_nms)))
        cand_full, cand_small, cand_score = [], [], []
        for start in range(0, len(grid_in), batch):
            pts = grid_in[start:start + batch]
            n_real = len(pts)
            if self.fixed_batch and n_real < batch:
                pts = np.concatenate([pts, np.repeat(pts[-1:], batch - n_real, 0)])
            logits, ious = self._decode(emb, pts, h0, w0, n_real)
            hi = logits > c.mask_threshold + c.stability_offset
            lo = logits > c.mask_threshold - c.stability_offset
            stab = hi.sum((2, 3)) / np.maximum(lo.sum((2, 3)), 1)
            ok = (ious >= c.pred_iou_thresh) & (stab >= c.stability_score_thresh)
            for bi, mi in zip(*np.nonzero(ok), strict=True):
                lg = logits[bi, mi]
                if lg.shape != (h0, w0):
                    lg = cv2.resize(lg, (w0, h0), interpolation=cv2.INTER_LINEAR)
                m = lg > c.mask_threshold
                if m.sum() < c.min_area_px:
                    continue
                cand_full.append(m)
                cand_small.append(cv2.resize(m.astype(np.uint8), nms_hw[::-1],
                                             interpolation=cv2.INTER_NEAREST).astype(bool))
                cand_score.append(float(ious[bi, mi]) + 1e-3 * float(stab[bi, mi]))
        if not cand_full:
            return [], np.zeros(0, np.float32)
        order = np.argsort(-np.asarray(cand_score), kind="stable")
        small = np.stack([cand_small[i].ravel() for i in order]).astype(np.float32)
        area = small.sum(1)
        kept: list[int] = []
        for row in range(len(order)):
            if kept:
                inter = small[kept] @ small[row]
                iou = inter / np.maximum(area[kept] + area[row] - inter, 1e-9)
                if (iou >= c.nms_iou).any():
                    continue
            kept.append(row)
        masks = [cand_full[order[r]] for r in kept]
        scores = np.asarray([cand_score[order[r]] for r in kept], np.float32)
        return masks, scores


def paint_masks(masks: list[np.ndarray], shape: tuple[int, int], min_area_px: int) -> np.ndarray:
    """Non-overlapping segment ids: paint largest first so smaller masks stay on top.

    Returns (H, W) int32, -1 unassigned, ids 0..S-1 renumbered in order of the input list.
    """
    seg = np.full(shape, -1, np.int32)
    for i in np.argsort([-m.sum() for m in masks], kind="stable"):
        seg[masks[i]] = i
    out = np.full(shape, -1, np.int32)
    new = 0
    for i in range(len(masks)):
        sel = seg == i
        if sel.sum() >= max(min_area_px, 1):
            out[sel] = new
            new += 1
    return out


def match_masks_to_detections(
    segment_id: np.ndarray, dets: Detections, min_iou: float
) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Label each segment with the detection whose box has the highest IoU with the segment's mask.

    IoU(mask, box) = |mask ∩ box| / (|mask| + |box| - |mask ∩ box|) in pixels (paper §3 Stage 2).

    Returns labels (S,), scores (S,) float32 (the detection's score, 0 if unmatched) and the
    matched IoU (S,) float32. Segments with best IoU < ``min_iou`` are ``"unknown"``.
    """
    n = int(segment_id.max()) + 1 if segment_id.size and segment_id.max() >= 0 else 0
    labels = ["unknown"] * n
    scores = np.zeros(n, np.float32)
    best_iou = np.zeros(n, np.float32)
    if n == 0 or len(dets) == 0:
        return labels, scores, best_iou
    h, w = segment_id.shape
    flat = segment_id.ravel()
    valid = flat >= 0
    area = np.bincount(flat[valid], minlength=n).astype(np.float64)
    for d in range(len(dets)):
        x0, y0, x1, y1 = dets.boxes[d]
        c0, r0 = int(np.floor(x0)), int(np.floor(y0))
        c1, r1 = int(np.ceil(x1)), int(np.ceil(y1))
        c0, r0, c1, r1 = max(c0, 0), max(r0, 0), min(c1, w), min(r1, h)
        if c1 <= c0 or r1 <= r0:
            continue
        sub = segment_id[r0:r1, c0:c1].ravel()
        inter = np.bincount(sub[sub >= 0], minlength=n).astype(np.float64)
        box_area = float((r1 - r0) * (c1 - c0))
        iou = inter / np.maximum(area + box_area - inter, 1e-9)
        better = (iou > best_iou) & (iou >= min_iou)
        for s in np.flatnonzero(better):
            labels[s] = dets.labels[d]
            scores[s] = dets.scores[d]
            best_iou[s] = iou[s]
    return labels, scores, best_iou


@SEGMENT_BACKENDS.register("sam2-gdino")
class Sam2GdinoSegments:
    """Stage 2 backend ``sam2-gdino``.

    Options
    -------
    sam2 : dict — :class:`Sam2Config` fields (``encoder_path``, ``decoder_path`` required).
    gdino : dict — :class:`GroundingDinoConfig` fields (``model_path``, ``vocab_path`` required).
    sam2_<field>, gdino_<field> — the same fields as flat options (e.g. ``sam2_encoder_path``,
        ``gdino_vocab_path``), so a YAML config can stay flat; they override the dicts.
    match_iou : float — minimum mask-to-box IoU for a label (default 0.25).
    keep_unmatched : bool — keep segments without a matching detection as ``unknown`` (default
        True; they still carry geometry) or drop them (pixels -1).

    The returned ``Segments.detections`` holds the Grounding DINO :class:`Detections` and
    ``Segments.info`` a JSON-able summary (mask and detection counts, detections as
    ``[label, score, x0, y0, x1, y1]``).
    """

    def __init__(self, sam2: dict | None = None, gdino: dict | None = None,
                 match_iou: float = 0.25, keep_unmatched: bool = True, **flat) -> None:
        sam2 = dict(sam2 or {})
        gdino = dict(gdino or {})
        for key, value in flat.items():
            if key.startswith("sam2_"):
                sam2[key[5:]] = value
            elif key.startswith("gdino_"):
                gdino[key[6:]] = value
            else:
                raise ValueError(
                    f"sam2-gdino: unknown option {key!r}; use sam2/gdino dicts, sam2_<field>, "
                    "gdino_<field>, match_iou, keep_unmatched"
                )
        if not sam2 or not gdino:
            raise ValueError(
                "sam2-gdino backend needs options sam2: {encoder_path, decoder_path} and "
                "gdino: {model_path, vocab_path} (or sam2_encoder_path, ... as flat options) "
                "pointing at your ONNX exports"
            )
        if not 0 < match_iou <= 1:
            raise ValueError(f"sam2-gdino: match_iou must lie in (0, 1], got {match_iou}")
        self.sam = Sam2AutoMasks(_options(Sam2Config, sam2, "sam2-gdino option sam2"))
        self.gdino = GroundingDino(_options(GroundingDinoConfig, gdino,
                                            "sam2-gdino option gdino"))
        self.match_iou = float(match_iou)
        self.keep_unmatched = bool(keep_unmatched)

    def check(self) -> str:
        """Run one small synthetic image (96 × 128 px: a red door on a grey wall) through the SAM2
        encoder, one decoder batch and Grounding DINO; a one-line summary (``sim2radar models
        check``). Raises what they raise."""
        import time

        rgb = np.full((96, 128, 3), 180, np.uint8)
        rgb[24:96, 40:72] = (150, 30, 30)
        t0 = time.perf_counter()
        sam = self.sam.probe(rgb)
        dets = self.gdino.detect(rgb)
        h, w = self.gdino.input_hw
        return (f"{sam}; Grounding DINO ({self.gdino.model.path.name}) ran at {h}x{w} "
                f"(input_hw), {len(dets)} detection(s); {time.perf_counter() - t0:.2f} s")

    def segment(self, frame: FrameInput, depth: DepthResult) -> Segments:
        masks, _ = self.sam.generate(frame.rgb)
        if not masks:
            raise ReconstructionInputError(
                f"{frame.name}: SAM2 produced no masks (points_per_side="
                f"{self.sam.config.points_per_side}, pred_iou_thresh="
                f"{self.sam.config.pred_iou_thresh}); lower the thresholds or check the image"
            )
        seg = paint_masks(masks, frame.shape, self.sam.config.min_area_px)
        dets = self.gdino.detect(frame.rgb)
        labels, scores, _ = match_masks_to_detections(seg, dets, self.match_iou)
        if not self.keep_unmatched:
            keep = [i for i, lab in enumerate(labels) if lab != "unknown"]
            remap = np.full(len(labels) + 1, -1, np.int32)
            remap[np.asarray(keep, int)] = np.arange(len(keep), dtype=np.int32)
            seg = np.where(seg >= 0, remap[seg], -1).astype(np.int32)
            labels = [labels[i] for i in keep]
            scores = scores[keep] if keep else np.zeros(0, np.float32)
        info = {
            "backend": "sam2-gdino",
            "n_masks": len(masks),
            "n_segments": len(labels),
            "n_labelled": int(sum(lab != "unknown" for lab in labels)),
            "gdino_input_hw": list(self.gdino.input_hw),
            "detections": [[lab, float(sc), *map(float, box)] for lab, sc, box in
                           zip(dets.labels, dets.scores, dets.boxes, strict=True)],
        }
        log.info("%s: %d SAM2 segments, %d detections, %d labelled", frame.name,
                 len(labels), len(dets), sum(lab != "unknown" for lab in labels))
        return Segments(seg.astype(np.int32), tuple(labels), np.asarray(scores, np.float32),
                        info=info, detections=dets)
