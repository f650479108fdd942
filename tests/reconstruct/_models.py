"""Test fixtures for the production reconstruction backends (helper E1).

* An analytic corridor scene (axis-aligned planes + one cabinet box) ray-cast from the camera:
  RGB, exact z-depth, face ids, and a 16-beam-like LiDAR scan — the ground truth for the depth
  backends.
* Tiny torch models exported to ONNX with the public input/output signatures of MoGe-2, SAM2
  (encoder + decoder) and Grounding DINO, producing known outputs, so the backends' loading,
  pre- and post-processing are tested without any real weights.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim2radar.camera import CameraIntrinsics

# ---------------------------------------------------------------------------------------------
# Analytic corridor
# ---------------------------------------------------------------------------------------------

#: Corridor interior [m] in the camera frame (x right, y down, z forward); camera at the origin.
CORRIDOR_LO = np.array([-1.2, -1.3, -1.0])
CORRIDOR_HI = np.array([1.0, 1.5, 14.0])
#: A cabinet standing against the left wall [m].
CABINET_LO = np.array([-1.2, 0.3, 3.0])
CABINET_HI = np.array([-0.6, 1.5, 4.0])

# face ids: 0..5 corridor (-x wall, +x wall, ceiling, floor, back, end wall), 6..11 cabinet faces
FACE_COLOURS = np.array(
    [
        [200, 190, 170], [185, 175, 160], [240, 240, 235], [110, 110, 120], [90, 90, 90],
        [150, 160, 200],
        [60, 90, 140], [70, 100, 150], [50, 80, 130], [55, 85, 135], [65, 95, 145],
        [45, 75, 125],
    ],
    dtype=np.float64,
)


def _raycast(dirs: np.ndarray, with_cabinet: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Ray parameter t (distance along unit-less dir) and face id for rays from the origin."""
    d = np.where(np.abs(dirs) < 1e-12, 1e-12, dirs)
    # Exit of the corridor box (we are inside it).
    t_lo = CORRIDOR_LO / d
    t_hi = CORRIDOR_HI / d
    t_far = np.maximum(t_lo, t_hi)
    axis = np.argmin(t_far, axis=1)
    t = t_far[np.arange(len(d)), axis]
    positive_side = t_hi[np.arange(len(d)), axis] >= t_lo[np.arange(len(d)), axis]
    face = 2 * axis + positive_side.astype(int)
    if with_cabinet:
        c_lo = CABINET_LO / d
        c_hi = CABINET_HI / d
        t_near = np.minimum(c_lo, c_hi)
        t_out = np.maximum(c_lo, c_hi).min(axis=1)
        t_in = t_near.max(axis=1)
        hit = (t_in <= t_out) & (t_in > 0) & (t_in < t)
        c_axis = np.argmax(t_near, axis=1)
        c_pos = c_hi[np.arange(len(d)), c_axis] < c_lo[np.arange(len(d)), c_axis]
        t = np.where(hit, t_in, t)
        face = np.where(hit, 6 + 2 * c_axis + c_pos.astype(int), face)
    return t, face


def rotation_deg(axis: int, deg: float) -> np.ndarray:
    """(3, 3) rotation by ``deg`` about camera axis ``axis`` (0: x right, 2: z forward)."""
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    i, j = [a for a in range(3) if a != axis]
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def corridor_intrinsics(width: int = 96, height: int = 72, hfov_deg: float = 70.0):
    return CameraIntrinsics.from_fov(width, height, hfov_deg)


def render_corridor(k: CameraIntrinsics, with_cabinet: bool = True, noise: float = 2.0, seed=0):
    """RGB (H, W, 3) uint8, z-depth (H, W) float32 [m], face id (H, W) int of the corridor."""
    u = np.arange(k.width) + 0.5
    v = np.arange(k.height) + 0.5
    uu, vv = np.meshgrid(u, v)
    dirs = np.stack([(uu - k.cx) / k.fx, (vv - k.cy) / k.fy, np.ones_like(uu)], -1).reshape(-1, 3)
    t, face = _raycast(dirs, with_cabinet)
    depth = (t * dirs[:, 2]).reshape(k.height, k.width).astype(np.float32)
    face = face.reshape(k.height, k.width)
    rng = np.random.default_rng(seed)
    rgb = FACE_COLOURS[face] + rng.normal(0, noise, (k.height, k.width, 3))
    return np.clip(rgb, 0, 255).astype(np.uint8), depth, face


def lidar_scan(
    n_beams: int = 16,
    elev_deg: tuple[float, float] = (-30.0, 30.0),
    az_step_deg: float = 0.4,
    az_half_deg: float = 60.0,
    with_cabinet: bool = True,
) -> np.ndarray:
    """A 16-beam-like spinning LiDAR at the camera origin: (N, 3) float32 points [m]."""
    el = np.radians(np.linspace(elev_deg[0], elev_deg[1], n_beams))
    az = np.radians(np.arange(-az_half_deg, az_half_deg + 1e-9, az_step_deg))
    ee, aa = np.meshgrid(el, az, indexing="ij")
    dirs = np.stack(
        [np.cos(ee) * np.sin(aa), -np.sin(ee), np.cos(ee) * np.cos(aa)], -1
    ).reshape(-1, 3)
    t, _ = _raycast(dirs, with_cabinet)
    return (dirs * t[:, None]).astype(np.float32)


# ---------------------------------------------------------------------------------------------
# Tiny ONNX models
# ---------------------------------------------------------------------------------------------


def export_moge_like(
    path: Path,
    *,
    plane: tuple[float, float, float],
    ref_intrinsics: CameraIntrinsics,
    scale: float,
    shift: float,
    reported_metric_scale: float | None = None,
    output_names: tuple[str, ...] = ("points", "normal", "mask", "metric_scale"),
    input_names: tuple[str, ...] = ("image", "num_tokens"),
) -> Path:
    """Export a tiny model with MoGe-2's ONNX signature whose output is a known affine point map.

    The true scene is the plane ``1/Z = a x_n + b y_n + c`` seen by a camera with
    ``ref_intrinsics`` (``x_n = (u - cx) / fx``, ``y_n = (v - cy) / fy`` at pixel centres; the
    model rescales the intrinsics to the H, W it is fed). MoGe's convention is
    ``P_metric = (points + (0, 0, shift)) * metric_scale``, so the model outputs
    ``points = P_true / scale - (0, 0, shift)``, ``mask`` = 1, ``normal`` = (0, 0, -1) and
    ``metric_scale = reported_metric_scale`` (default ``scale``: a perfect metric head).

    Inputs: ``image`` (B, 3, H, W) float32 in [0, 1], ``num_tokens`` int64 scalar.
    Outputs: ``points`` (B, H, W, 3), ``normal`` (B, H, W, 3), ``mask`` (B, H, W),
    ``metric_scale`` (B,).
    """
    import torch

    a, b, c = plane
    k = ref_intrinsics
    ms = scale if reported_metric_scale is None else reported_metric_scale

    class MoGeLike(torch.nn.Module):
        def forward(self, image, num_tokens):
            ones = torch.ones_like(image[0, 0])  # (H, W), keeps H and W dynamic in the graph
            u = ones.cumsum(1) - 0.5
            v = ones.cumsum(0) - 0.5
            sx = ones.sum(1)[0] / k.width
            sy = ones.sum(0)[0] / k.height
            xn = (u - k.cx * sx) / (k.fx * sx)
            yn = (v - k.cy * sy) / (k.fy * sy)
            z = 1.0 / (a * xn + b * yn + c)
            p = torch.stack([xn * z, yn * z, z - shift * scale], -1) / scale
            p = p[None] * torch.ones_like(image[:, :1, :1, :1]).permute(0, 2, 3, 1)
            mask = (image.mean(1) >= -1.0).to(torch.float32)
            normal = torch.zeros_like(p) + torch.tensor([0.0, 0.0, -1.0])
            msc = torch.ones_like(image[:, 0, 0, 0]) * ms + num_tokens.to(torch.float32) * 0.0
            return p, normal, mask, msc

    dummy = (torch.rand(1, 3, 24, 32), torch.tensor(1800, dtype=torch.int64))
    _export(MoGeLike().eval(), dummy, path, input_names, output_names,
            {input_names[0]: {0: "batch", 2: "height", 3: "width"}})
    return path


def _export(model, dummy, path, input_names, output_names, dynamic_axes=None) -> None:
    """torch.onnx.export with the TorchScript exporter, quietly."""
    import warnings

    import torch

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            model,
            dummy,
            str(path),
            input_names=list(input_names),
            output_names=list(output_names),
            dynamic_axes=dynamic_axes,
            opset_version=17,
            dynamo=False,
        )


# ---------------------------------------------------------------------------------------------
# SAM2 and Grounding DINO look-alikes
# ---------------------------------------------------------------------------------------------

#: Synthetic 64 x 64 scene for segmentation: name -> (row0, row1, col0, col1, RGB). Painted in
#: order; boundaries on multiples of 4 px (the tiny SAM2's 16 x 16 embedding grid).
SEG_SCENE = {
    "ceiling": (0, 8, 0, 64, (240, 240, 235)),
    "wall": (8, 48, 0, 64, (200, 190, 170)),
    "floor": (48, 64, 0, 64, (110, 110, 120)),
    "door": (12, 48, 8, 24, (150, 30, 30)),
    "window": (12, 28, 40, 56, (120, 170, 230)),
    "fire_extinguisher": (32, 40, 32, 36, (230, 10, 10)),
}
SEG_HW = (64, 64)
SAM_INPUT = 64  # the tiny SAM2's square input size [px]

#: BERT-like vocabulary for the tiny Grounding DINO (id = index).
TINY_VOCAB = [
    "[PAD]", "[UNK]", "[CLS]", "[SEP]", "[MASK]", ".", ",", "?", "door", "wall", "floor",
    "ceiling", "window", "fire", "ex", "##ting", "##uish", "##er", "hand", "##rail", "cat",
]


def render_seg_scene() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """RGB (64, 64, 3) uint8 and the visible mask of each named region."""
    h, w = SEG_HW
    rgb = np.zeros((h, w, 3), np.uint8)
    owner = np.empty((h, w), object)
    for name, (r0, r1, c0, c1, col) in SEG_SCENE.items():
        rgb[r0:r1, c0:c1] = col
        owner[r0:r1, c0:c1] = name
    return rgb, {name: owner == name for name in SEG_SCENE}


def export_sam2_like(encoder_path: Path, decoder_path: Path, *, with_orig_size: bool = True,
                     onnxruntime_names: bool = False):
    """Tiny SAM2 encoder/decoder pair with the samexporter signatures (input size 64).

    ``onnxruntime_names``: the signatures of onnxruntime's own SAM2 exporter
    (``onnxruntime/python/tools/transformers/models/sam2``) instead: encoder outputs
    ``image_features_0``, ``image_features_1``, ``image_embeddings``; decoder inputs those +
    ``point_coords``, ``point_labels`` (int32), ``input_masks``, ``has_input_masks``,
    ``original_image_size`` (int32); outputs ``masks`` (bool: the logits resized to the original
    size and thresholded at 0), ``iou_predictions``, ``low_res_masks`` (the logits).

    Encoder: ``image`` (1, 3, 64, 64) -> ``image_embed`` (1, 3, 16, 16) (4x4 average colour),
    ``high_res_feats_0`` (1, 1, 64, 64), ``high_res_feats_1`` (1, 1, 32, 32).
    Decoder: the mask of a point (logits saturating at +-6) is the set of embedding cells whose colour is within 0.3
    (normalised units) of the colour under the point: a flat-colour region. Three multimask
    outputs with thresholds 0.3 / 0.1 / 1.0 and predicted IoUs 0.95 / 0.6 / 0.5; masks come out at
    32 x 32 (upsampled x2), like SAM's low-resolution masks that the caller resizes.
    """
    import torch
    import torch.nn.functional as F  # noqa: N812

    class Enc(torch.nn.Module):
        def forward(self, image):
            emb = F.avg_pool2d(image, 4)
            return emb, image[:, :1], F.avg_pool2d(image[:, :1], 2)

    class Dec(torch.nn.Module):
        def forward(self, image_embed, hr0, hr1, point_coords, point_labels, mask_input,
                    has_mask_input, *orig):
            e = image_embed[0].reshape(3, 256)  # (3, 256)
            ix = torch.clamp(torch.floor(point_coords[:, 0, 0] / 4), 0, 15).long()
            iy = torch.clamp(torch.floor(point_coords[:, 0, 1] / 4), 0, 15).long()
            col = torch.index_select(e, 1, iy * 16 + ix)  # (3, B)
            d = torch.sqrt(((e[:, None, :] - col[:, :, None]) ** 2).sum(0) + 1e-12)  # (B, 256)
            extra = (hr0.mean() + hr1.mean() + mask_input.mean() + has_mask_input.sum()
                     + point_labels.sum()) * 0.0
            if orig:
                extra = extra + orig[0].sum().to(torch.float32) * 0.0
            logits = 6 * torch.tanh(torch.stack([20 * (0.3 - d), 20 * (0.1 - d), 20 * (1.0 - d)], 1))
            logits = logits + extra
            logits = F.interpolate(logits.reshape(-1, 3, 16, 16), scale_factor=2.0,
                                   mode="nearest")
            ious = torch.ones_like(logits[:, :, 0, 0]) * torch.tensor([0.95, 0.6, 0.5])
            return logits, ious

    if onnxruntime_names:
        class EncOrt(torch.nn.Module):
            def forward(self, image):
                emb, hr0, hr1 = Enc()(image)
                return hr0, hr1, emb

        class DecOrt(torch.nn.Module):
            def forward(self, image_features_0, image_features_1, image_embeddings, point_coords,
                        point_labels, input_masks, has_input_masks, original_image_size):
                logits, ious = Dec()(image_embeddings, image_features_0, image_features_1,
                                     point_coords, point_labels.to(torch.float32), input_masks,
                                     has_input_masks)
                size = (original_image_size[0], original_image_size[1])
                masks = F.interpolate(logits, size=size, mode="bilinear") > 0.0
                return masks, ious, logits

        _export(EncOrt().eval(), (torch.rand(1, 3, SAM_INPUT, SAM_INPUT),), encoder_path,
                ["image"], ["image_features_0", "image_features_1", "image_embeddings"])
        names = ["image_features_0", "image_features_1", "image_embeddings", "point_coords",
                 "point_labels", "input_masks", "has_input_masks", "original_image_size"]
        dummy = (torch.rand(1, 1, 64, 64), torch.rand(1, 1, 32, 32), torch.rand(1, 3, 16, 16),
                 torch.rand(2, 1, 2) * 64, torch.ones(2, 1, dtype=torch.int32),
                 torch.zeros(2, 1, 16, 16), torch.zeros(1),
                 torch.tensor(list(SEG_HW), dtype=torch.int32))
        _export(DecOrt().eval(), dummy, decoder_path, names,
                ["masks", "iou_predictions", "low_res_masks"],
                {"point_coords": {0: "num_labels", 1: "num_points"},
                 "point_labels": {0: "num_labels", 1: "num_points"},
                 "input_masks": {0: "num_labels"}, "has_input_masks": {0: "num_labels"},
                 "masks": {0: "num_labels", 2: "original_image_height",
                           3: "original_image_width"},
                 "low_res_masks": {0: "num_labels"}, "iou_predictions": {0: "num_labels"}})
        return encoder_path, decoder_path
    _export(Enc().eval(), (torch.rand(1, 3, SAM_INPUT, SAM_INPUT),), encoder_path, ["image"],
            ["image_embed", "high_res_feats_0", "high_res_feats_1"])
    names = ["image_embed", "high_res_feats_0", "high_res_feats_1", "point_coords",
             "point_labels", "mask_input", "has_mask_input"]
    dummy = [torch.rand(1, 3, 16, 16), torch.rand(1, 1, 64, 64), torch.rand(1, 1, 32, 32),
             torch.rand(2, 1, 2) * 64, torch.ones(2, 1), torch.zeros(2, 1, 16, 16),
             torch.zeros(1)]
    if with_orig_size:
        names.append("orig_im_size")
        dummy.append(torch.tensor(list(SEG_HW), dtype=torch.int64))
    _export(Dec().eval(), tuple(dummy), decoder_path, names, ["masks", "iou_predictions"],
            {"point_coords": {0: "b", 1: "p"}, "point_labels": {0: "b", 1: "p"},
             "mask_input": {0: "b"}})
    return encoder_path, decoder_path


def seg_scene_boxes() -> dict[str, tuple[float, float, float, float]]:
    """Normalised (cx, cy, w, h) boxes of the regions' full rectangles."""
    out = {}
    for name, (r0, r1, c0, c1, _) in SEG_SCENE.items():
        h, w = SEG_HW
        out[name] = ((c0 + c1) / 2 / w, (r0 + r1) / 2 / h, (c1 - c0) / w, (r1 - r0) / h)
    return out


def export_gdino_like(path: Path, queries: list[tuple[str, int, tuple]], *, img_hw=SEG_HW):
    """Tiny Grounding DINO with the public ONNX signature.

    Each query ``(token, position_id, box_cxcywh)`` fires (logit +8, else -8) on the text
    positions whose token id is ``TINY_VOCAB.index(token)`` *and* whose position id (restarting
    in every phrase) equals ``position_id``; its box is ``box_cxcywh``. Logits are (1, Q, 256).
    """
    import torch

    tok = torch.tensor([TINY_VOCAB.index(t) for t, _, _ in queries], dtype=torch.int64)
    pid = torch.tensor([p for _, p, _ in queries], dtype=torch.int64)
    boxes = torch.tensor([b for _, _, b in queries], dtype=torch.float32)

    class Gd(torch.nn.Module):
        def forward(self, img, input_ids, attention_mask, position_ids, token_type_ids,
                    text_token_mask):
            ids = input_ids[0]
            pos = torch.ones_like(ids).cumsum(0) - 1  # (T,) text positions
            onehot = (pos[:, None] == torch.arange(256)[None, :]).to(torch.float32)  # (T, 256)
            ok = (ids[None, :] == tok[:, None]) & (position_ids[0][None, :] == pid[:, None])
            ok = ok & attention_mask[0][None, :].to(torch.bool)
            ok = ok & text_token_mask[0].diagonal()[None, :].to(torch.bool)
            logits = ok.to(torch.float32) @ onehot * 16.0 - 8.0
            logits = logits + token_type_ids.sum().to(torch.float32) * 0.0
            b = boxes + img.mean() * 0.0
            return logits[None], b[None]

    t = 6
    dummy = (torch.rand(1, 3, *img_hw), torch.zeros(1, t, dtype=torch.int64),
             torch.ones(1, t, dtype=torch.bool), torch.zeros(1, t, dtype=torch.int64),
             torch.zeros(1, t, dtype=torch.int64), torch.ones(1, t, t, dtype=torch.bool))
    names = ["img", "input_ids", "attention_mask", "position_ids", "token_type_ids",
             "text_token_mask"]
    _export(Gd().eval(), dummy, path, names, ["logits", "boxes"],
            {n: {1: "t"} for n in names[1:5]} | {"text_token_mask": {1: "t", 2: "t"}})
    return path


def export_gdino_swin_like(path: Path, *, export_hw: tuple[int, int] = (800, 1200)) -> Path:
    """Grounding DINO look-alike that behaves like a public Swin export: its ``img`` input
    *declares* dynamic H, W, but the graph reshapes the image to the constant
    ``(3, *export_hw)`` it was traced at (as Swin's window partition does), so onnxruntime fails
    with a Reshape error at any other size.

    One query fires on the token "door" (position 0 in its phrase); its box is *measured* from
    the image: the bounding box, normalised by ``export_hw``, of the pixels whose ImageNet-
    normalised red channel exceeds 0.5 (a saturated red patch on a dark background).
    """
    import torch

    eh, ew = export_hw
    door = TINY_VOCAB.index("door")

    class SwinLike(torch.nn.Module):
        def forward(self, img, input_ids, attention_mask, position_ids, token_type_ids,
                    text_token_mask):
            x = img.reshape(3, eh, ew)  # constant shape: only the traced size fits
            red = (x[0] > 0.5).to(torch.float32)  # (eh, ew)
            cols, rows = red.amax(0), red.amax(1)
            ci, ri = torch.arange(ew, dtype=torch.float32), torch.arange(eh, dtype=torch.float32)
            c0 = torch.argmax(cols * (ew - ci)).to(torch.float32)  # first red column
            c1 = torch.argmax(cols * (ci + 1)).to(torch.float32) + 1  # one past the last
            r0 = torch.argmax(rows * (eh - ri)).to(torch.float32)
            r1 = torch.argmax(rows * (ri + 1)).to(torch.float32) + 1
            box = torch.stack([(c0 + c1) / 2 / ew, (r0 + r1) / 2 / eh, (c1 - c0) / ew,
                               (r1 - r0) / eh])
            ids = input_ids[0]
            pos = torch.ones_like(ids).cumsum(0) - 1
            onehot = (pos[:, None] == torch.arange(256)[None, :]).to(torch.float32)  # (T, 256)
            ok = (ids == door) & (position_ids[0] == 0) & attention_mask[0].to(torch.bool)
            ok = ok & text_token_mask[0].diagonal().to(torch.bool)
            logits = ok.to(torch.float32)[None] @ onehot * 16.0 - 8.0  # (1, 256)
            logits = logits + token_type_ids.sum().to(torch.float32) * 0.0
            return logits[None], box[None, None]

    t = 6
    dummy = (torch.rand(1, 3, eh, ew), torch.zeros(1, t, dtype=torch.int64),
             torch.ones(1, t, dtype=torch.bool), torch.zeros(1, t, dtype=torch.int64),
             torch.zeros(1, t, dtype=torch.int64), torch.ones(1, t, t, dtype=torch.bool))
    names = ["img", "input_ids", "attention_mask", "position_ids", "token_type_ids",
             "text_token_mask"]
    _export(SwinLike().eval(), dummy, path, names, ["logits", "boxes"],
            {"img": {2: "height", 3: "width"}} | {n: {1: "t"} for n in names[1:5]}
            | {"text_token_mask": {1: "t", 2: "t"}})
    return path
