"""Bring your own radar data: the formats radar datasets ship in, converted into the OpenPCDet
custom layout (:mod:`sim2radar.datasets.openpcdet`) that ``sweep`` and ``train`` read.

Points (one file per frame, the file stem is the frame id):

* ``.bin`` — KITTI-style raw float32 rows (``x y z intensity`` and more: View-of-Delft radar
  has 7 columns ``x y z RCS v_r v_r_compensated time``); the row width is ``point_dims``.
* ``.pcd`` — Point Cloud Library files, read with ``pypcd4`` (ASCII, binary and
  binary-compressed); the fields to keep are named (``x y z`` first).
* ``.npy`` — ``(N, C)`` arrays.

Labels (``label_2/`` or ``labels/``, one ``<frame id>.txt`` per frame):

* KITTI object labels ``type truncated occluded alpha x1 y1 x2 y2 h w l x y z ry [score]``, in
  the rectified camera frame (x right, y down, z forward; the location is the box's bottom
  centre). They are moved into the point cloud's frame with the frame's ``calib/<id>.txt``
  (``R0_rect``, ``Tr_velo_to_cam``), as OpenPCDet's ``boxes3d_kitti_camera_to_lidar`` does:
  centre lifted by h/2, dimensions ``l w h``, heading the facing direction rotated into the
  point cloud's frame (``-(ry + pi/2)`` for aligned axes).
* OpenPCDet custom labels ``x y z dx dy dz heading class`` (already in the point cloud's frame).

Class names are matched case-insensitively against the detector's classes (``Door`` becomes
``door``); ``DontCare`` is dropped; any other class is an error naming the file, the label and
the known classes, unless ``drop_other_classes``. Splits come from the source's
``ImageSets/*.txt`` when it has them — a missing ``test.txt`` is carved from ``val`` (seeded
half, said in ``dataset.json``) — else a seeded 70/15/15 split of the frame ids.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import random
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sim2radar.datasets.openpcdet import DatasetError, Frame, write_dataset, write_metadata
from sim2radar.datasets.splits import split_groups

__all__ = ["FORMATS", "ImportSettings", "import_dataset", "kitti_camera_boxes_to_lidar",
           "read_kitti_calib", "read_label_file", "read_point_file"]

log = logging.getLogger(__name__)

#: Point file formats, by suffix.
FORMATS = {"bin": ".bin", "pcd": ".pcd", "npy": ".npy"}
_POINT_FOLDERS = ("velodyne", "points", "radar", "pointclouds")
_LABEL_FOLDERS = ("label_2", "labels")
_IGNORED_CLASSES = ("dontcare",)


@dataclasses.dataclass(frozen=True)
class ImportSettings:
    """How to read a source folder.

    Attributes
    ----------
    fmt : ``"bin"``, ``"pcd"`` or ``"npy"`` (None: the suffix found in the points folder).
    point_dims : floats per ``.bin`` row (required for ``.bin``: the files have no header).
    columns : indices of the ``.bin`` / ``.npy`` columns to keep (x y z first; default the
        first four, or all when fewer).
    fields : names of the ``.pcd`` fields to keep (default ``x y z`` + ``intensity`` when
        present).
    classes : the detector's class names (labels are matched to them case-insensitively).
    drop_other_classes : drop labels of other classes (counted) instead of refusing them.
    domain : what the data is (``dataset.json``'s ``domain``, e.g. ``"measured"``).
    seed : seed of the split when the source has none (and of a test split carved from val).
    """

    fmt: str | None = None
    point_dims: int | None = None
    columns: tuple[int, ...] | None = None
    fields: tuple[str, ...] | None = None
    classes: tuple[str, ...] = ("door",)
    drop_other_classes: bool = False
    domain: str = "measured"
    seed: int = 0


# ---------------------------------------------------------------------------------- points
def read_point_file(path: Path, settings: ImportSettings) -> np.ndarray:
    """One frame's points as (N, C) float32, x y z first (the file named in every error)."""
    suffix = path.suffix.lower()
    if suffix == ".bin":
        if settings.point_dims is None:
            raise DatasetError(f"{path}: a .bin file has no header saying its row width; give "
                               "--point-dims (KITTI lidar 4, View-of-Delft radar 7): a wrong "
                               "width scrambles the points silently")
        raw = np.fromfile(path, dtype=np.float32)
        if raw.size % settings.point_dims:
            raise DatasetError(f"{path}: {raw.size} float32 values are not rows of "
                               f"{settings.point_dims}; give --point-dims (KITTI 4, "
                               "View-of-Delft radar 7)")
        pts = raw.reshape(-1, settings.point_dims)
        return _columns(pts, path, settings)
    if suffix == ".npy":
        try:
            pts = np.load(path, allow_pickle=False)
        except Exception as exc:  # noqa: BLE001 - any read error is a bad file
            raise DatasetError(f"{path}: cannot read as .npy ({exc})") from None
        if pts.ndim != 2 or pts.shape[1] < 3:
            raise DatasetError(f"{path}: points must be (N, C>=3), got {pts.shape}")
        return _columns(pts.astype(np.float32), path, settings)
    if suffix == ".pcd":
        return _read_pcd(path, settings)
    raise DatasetError(f"{path}: unknown point format {suffix!r}; one of "
                       f"{sorted(FORMATS.values())}")


def _columns(pts: np.ndarray, path: Path, settings: ImportSettings) -> np.ndarray:
    cols = settings.columns or tuple(range(min(4, pts.shape[1])))
    if max(cols) >= pts.shape[1] or len(cols) < 3:
        raise DatasetError(f"{path}: columns {list(cols)} do not fit rows of {pts.shape[1]} "
                           "values (x y z first); fix --columns")
    out = np.ascontiguousarray(pts[:, list(cols)], dtype=np.float32)
    if not np.isfinite(out).all():
        raise DatasetError(f"{path}: {int((~np.isfinite(out)).any(axis=1).sum())} rows hold "
                           "NaN or inf; clean the file")
    return out


def _read_pcd(path: Path, settings: ImportSettings) -> np.ndarray:
    from pypcd4 import PointCloud

    try:
        pc = PointCloud.from_path(path)
    except Exception as exc:  # noqa: BLE001 - pypcd4 raises several kinds
        raise DatasetError(f"{path}: not a readable PCD file ({exc})") from None
    have = tuple(pc.fields)
    wanted = settings.fields or (("x", "y", "z", "intensity") if "intensity" in have
                                 else ("x", "y", "z"))
    missing = [f for f in wanted if f not in have]
    if missing or tuple(wanted[:3]) != ("x", "y", "z"):
        raise DatasetError(f"{path}: fields {list(wanted)} (x y z first) are not all in the "
                           f"file, which has {list(have)}; fix --fields")
    pts = np.asarray(pc.numpy(list(wanted)), np.float32).reshape(-1, len(wanted))
    if not np.isfinite(pts).all():
        pts = pts[np.isfinite(pts).all(axis=1)]  # PCD marks missing returns with NaN
    return pts


# ---------------------------------------------------------------------------------- labels
def read_kitti_calib(path: Path) -> np.ndarray:
    """``lidar -> rectified camera`` (4, 4) of a KITTI ``calib/<id>.txt``: ``R0_rect @
    Tr_velo_to_cam``."""
    if not path.is_file():
        raise DatasetError(f"{path}: KITTI labels are in the camera frame and need the frame's "
                           "calibration (R0_rect, Tr_velo_to_cam); add calib/<id>.txt")
    values: dict[str, np.ndarray] = {}
    for line in path.read_text().splitlines():
        name, _, rest = line.partition(":")
        if rest.strip():
            try:
                values[name.strip()] = np.array([float(v) for v in rest.split()])
            except ValueError:
                raise DatasetError(f"{path}: {name.strip()}: not numbers") from None
    try:
        tr = values["Tr_velo_to_cam"].reshape(3, 4)
    except (KeyError, ValueError):
        raise DatasetError(f"{path}: needs 'Tr_velo_to_cam: 12 numbers'") from None
    r0 = values.get("R0_rect", np.eye(3).ravel()).reshape(3, 3)
    v2c = np.eye(4)
    v2c[:3] = tr
    rect = np.eye(4)
    rect[:3, :3] = r0
    return rect @ v2c


def kitti_camera_boxes_to_lidar(boxes_cam: np.ndarray, lidar_to_rect: np.ndarray) -> np.ndarray:
    """(M, 7) KITTI camera boxes ``x y z l h w ry`` (bottom centre, rectified camera frame) ->
    (M, 7) ``x y z dx dy dz heading`` in the point cloud's frame (box centre)."""
    b = np.asarray(boxes_cam, np.float64).reshape(-1, 7)
    rect_to_lidar = np.linalg.inv(lidar_to_rect)
    xyz = (np.c_[b[:, :3], np.ones(len(b))] @ rect_to_lidar.T)[:, :3]
    length, height, width, ry = b[:, 3], b[:, 4], b[:, 5], b[:, 6]
    xyz[:, 2] += height / 2.0
    # the facing direction (cos ry, 0, -sin ry) in the camera, rotated into the point cloud's
    # frame: exact for any calibration; OpenPCDet's -(ry + pi/2) assumes aligned axes and is
    # off by the rig's rotation about the vertical (R0_rect's 1-2 deg on KITTI)
    facing = np.c_[np.cos(ry), np.zeros_like(ry), -np.sin(ry)] @ rect_to_lidar[:3, :3].T
    heading = np.arctan2(facing[:, 1], facing[:, 0])
    return np.c_[xyz, length, width, height, heading]


def read_label_file(path: Path, calib: Path | None) -> tuple[np.ndarray, list[str]]:
    """Boxes (M, 7) in the point cloud's frame and their raw class names, from a KITTI or an
    OpenPCDet custom label file (told apart per line: a KITTI line starts with its class)."""
    boxes, names, kitti = [], [], []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        try:
            float(parts[0])
            is_kitti = False
        except ValueError:
            is_kitti = True
        try:
            if is_kitti:
                if len(parts) not in (15, 16):
                    raise ValueError(f"{len(parts)} fields, a KITTI label has 15 (16 with a "
                                     "score)")
                height, width, length, x, y, z, ry = map(float, parts[8:15])
                kitti.append([x, y, z, length, height, width, ry])
                names.append(parts[0])
            else:
                if len(parts) != 8:
                    raise ValueError(f"{len(parts)} fields, a custom label has 8 (x y z dx dy "
                                     "dz heading class)")
                boxes.append([float(v) for v in parts[:7]])
                names.append(parts[7])
        except ValueError as exc:
            raise DatasetError(f"{path}: line {n}: {exc}") from None
    if kitti and boxes:
        raise DatasetError(f"{path}: mixes KITTI and custom label lines; use one format")
    if kitti:
        return kitti_camera_boxes_to_lidar(np.array(kitti), read_kitti_calib(calib)), names
    return np.array(boxes, np.float64).reshape(-1, 7), names


def _canonical(names: list[str], path: Path, settings: ImportSettings,
               counts: dict[str, int]) -> list[str | None]:
    """Each raw name as the detector's class (matched case-insensitively), None for a dropped
    label (counted in ``counts``)."""
    by_lower = {c.lower(): c for c in settings.classes}
    out: list[str | None] = []
    for name in names:
        c = by_lower.get(name.lower())
        if c is not None:
            out.append(c)
        elif name.lower() in _IGNORED_CLASSES or settings.drop_other_classes:
            counts[name] = counts.get(name, 0) + 1
            out.append(None)
        else:
            raise DatasetError(f"{path}: label class {name!r} is not one of the detector's "
                               f"classes {list(settings.classes)} (matched without case); drop "
                               "other classes with --drop-other-classes, or train a detector "
                               "with that class")
    return out


# ---------------------------------------------------------------------------------- source
def _find(root: Path, names: Sequence[str]) -> Path | None:
    for n in names:
        if (root / n).is_dir():
            return root / n
    return None


def _point_files(root: Path, settings: ImportSettings) -> tuple[Path, list[Path]]:
    folder = _find(root, _POINT_FOLDERS) or root
    suffixes = [FORMATS[settings.fmt]] if settings.fmt else list(FORMATS.values())
    for suffix in suffixes:
        files = sorted(p for p in folder.glob(f"*{suffix}") if p.is_file())
        if files:
            return folder, files
    raise DatasetError(f"{root}: no point files ({', '.join(suffixes)}) in {folder}; put them "
                       f"in one of {list(_POINT_FOLDERS)} or give the folder that holds them")


def _source_splits(root: Path, ids: list[str], seed: int) -> tuple[dict[str, list[str]],
                                                                   list[str]]:
    """The splits and what was said about them."""
    notes: list[str] = []
    sets = root / "ImageSets"
    known = set(ids)
    if sets.is_dir() and any(sets.glob("*.txt")):
        splits = {}
        for f in sorted(sets.glob("*.txt")):
            listed = [x.strip() for x in f.read_text().splitlines() if x.strip()]
            missing = [i for i in listed if i not in known]
            if missing:
                raise DatasetError(f"{f}: lists {len(missing)} frame(s) with no point file, "
                                   f"e.g. {missing[:3]}")
            splits[f.stem] = listed
        if "train" not in splits:
            raise DatasetError(f"{sets}: no train.txt; a dataset needs a train split")
        if "test" not in splits and len(splits.get("val", ())) >= 2:
            val = sorted(splits["val"])
            random.Random(seed).shuffle(val)
            half = math.ceil(len(val) / 2)
            splits["val"], splits["test"] = sorted(val[:half]), sorted(val[half:])
            notes.append(f"the source has no ImageSets/test.txt: test is {len(val) - half} "
                         f"frames carved from val (seeded, seed {seed}); val keeps {half}")
        return splits, notes
    splits = split_groups(ids, seed)
    notes.append(f"the source has no ImageSets: a seeded 70/15/15 split of the frame ids "
                 f"(seed {seed}); frames of one sequence may straddle splits, give ImageSets "
                 "to keep sequences apart")
    return splits, notes


def _frames(root: Path, files: list[Path], settings: ImportSettings,
            dropped: dict[str, int]) -> Iterator[Frame]:
    labels = _find(root, _LABEL_FOLDERS)
    if labels is None:
        raise DatasetError(f"{root}: no labels folder ({' or '.join(_LABEL_FOLDERS)})")
    calib = root / "calib"
    for f in files:
        lab = labels / f"{f.stem}.txt"
        if not lab.is_file():
            raise DatasetError(f"{lab}: no label file for {f.name} (write an empty file for a "
                               "frame without objects)")
        boxes, names = read_label_file(lab, calib / f"{f.stem}.txt")
        classes = _canonical(names, lab, settings, dropped)
        keep = [i for i, c in enumerate(classes) if c is not None]
        yield Frame(f.stem, read_point_file(f, settings), boxes[keep].astype(np.float32),
                    tuple(classes[i] for i in keep))


def import_dataset(source: str | Path, out: str | Path,
                   settings: ImportSettings | None = None) -> dict[str, Any]:
    """Convert the radar dataset in ``source`` into the OpenPCDet custom layout in ``out``
    (with ``dataset.json``: domain, source, formats, classes, dropped labels, splits).

    Every label file is read and checked before anything is written, so a bad label fails the
    import up front with its file and line. Returns the summary written to ``dataset.json``.

    Raises
    ------
    DatasetError — naming the file (and line or field) at fault and the fix.
    """
    settings = settings or ImportSettings()
    root, out = Path(source), Path(out)
    if not root.is_dir():
        raise DatasetError(f"{root}: source folder not found")
    if out.resolve() == root.resolve():
        raise DatasetError(f"{out}: the output must not be the source folder")
    folder, files = _point_files(root, settings)
    ids = [f.stem for f in files]
    splits, notes = _source_splits(root, ids, settings.seed)
    dropped: dict[str, int] = {}
    frames = list(_frames(root, files, settings, dropped))  # every file checked first
    write_dataset(out, frames, splits)
    n_boxes = sum(len(f.names) for f in frames)
    if n_boxes == 0:
        notes.append(f"no label of the classes {list(settings.classes)} was found")
    doc = {"domain": settings.domain, "source": str(root.resolve()),
           "imported_by": "sim2radar import",
           "points": {"folder": str(folder), "format": files[0].suffix.lstrip("."),
                      "point_dims": settings.point_dims if files[0].suffix == ".bin" else None,
                      "columns": list(settings.columns) if settings.columns else None,
                      "fields": list(settings.fields) if settings.fields else None,
                      "num_point_features": int(frames[0].points.shape[1]) if frames else None},
           "classes": list(settings.classes), "labels": n_boxes,
           "labels_dropped": dict(sorted(dropped.items())),
           "frames": len(frames), "splits": {k: len(v) for k, v in splits.items()},
           "notes": notes}
    write_metadata(out, doc)
    for note in notes:
        log.warning("%s: %s", out, note)
    return doc
