"""Reader and writer for OpenPCDet's *custom dataset* layout (how IFR radar data is shipped).

Layout (OpenPCDet ``docs/CUSTOM_DATASET_TUTORIAL.md``; ``test`` split added here)::

    ROOT/
      points/<frame_id>.npy     (N, C) float32 — x, y, z [m], extra features (e.g. intensity)
      labels/<frame_id>.txt     one box per line: ``x y z dx dy dz heading class_name``
                                [m, m, m, m, m, m, rad]; z is the box centre; may be empty
      ImageSets/train.txt       one frame id per line (also val.txt, test.txt)

Coordinates are the radar frame (x forward, y left, z up). Every problem is reported with the
file (and line) at fault and what to change.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim2radar.fileio import abandoned_temp_files, atomic_write, write_json

__all__ = [
    "DatasetError",
    "Frame",
    "OpenPCDetDataset",
    "read_labels",
    "read_points",
    "write_dataset",
    "write_frame",
    "write_split",
    "METADATA_FILE",
    "read_metadata",
    "UNDECLARED",
    "write_metadata",
]

log = logging.getLogger(__name__)

#: Optional description of a dataset folder (JSON): its ``domain`` ("measured", "proxy-real
#: (reference radar simulation)", "simulated (...)"), the radar, how labels were chosen, worlds
#: and splits. A folder without one (or without a ``domain`` in it) has the domain
#: :data:`UNDECLARED`: nothing guesses that it is measured radar.
METADATA_FILE = "dataset.json"
#: The ``domain`` of a dataset whose ``dataset.json`` declares none.
UNDECLARED = "undeclared"


class DatasetError(ValueError):
    """A dataset file is missing or malformed; the message names the file and the fix."""


@dataclass(frozen=True)
class Frame:
    """One radar frame with its labelled boxes.

    Attributes
    ----------
    frame_id : str — file stem under ``points/`` and ``labels/``.
    points : (N, C) float32 — x, y, z [m] and C - 3 extra features.
    boxes : (M, 7) float32 — ``x y z dx dy dz heading`` [m, rad], z = box centre.
    names : tuple of M class names.
    """

    frame_id: str
    points: np.ndarray
    boxes: np.ndarray
    names: tuple[str, ...]

    def select(self, class_names: Sequence[str]) -> Frame:
        """The same frame with only boxes of ``class_names``."""
        keep = [i for i, n in enumerate(self.names) if n in class_names]
        return Frame(self.frame_id, self.points, self.boxes[keep].reshape(-1, 7),
                     tuple(self.names[i] for i in keep))


def read_points(path: str | Path, num_point_features: int | None = None,
                drop_extra_columns: bool = False) -> np.ndarray:
    """Load ``points/<id>.npy`` as (N, C) float32, checking shape, dtype and finiteness.

    With ``drop_extra_columns``, a file with more columns than ``num_point_features`` keeps the
    first ``num_point_features`` (OpenPCDet's ``used_feature_list``: e.g. x y z intensity of a
    file that also has Doppler); fewer columns are always an error."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: point file missing (expected points/<frame_id>.npy)")
    try:
        pts = np.load(path, allow_pickle=False)
    except (ValueError, OSError) as exc:
        raise DatasetError(f"{path}: not a NumPy .npy array ({exc})") from exc
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise DatasetError(f"{path}: points must be an (N, C>=3) array [x y z ...], got {pts.shape}")
    if not np.issubdtype(pts.dtype, np.number):
        raise DatasetError(f"{path}: points must be numeric, got dtype {pts.dtype}")
    if drop_extra_columns and num_point_features is not None and pts.shape[1] > num_point_features:
        pts = pts[:, :num_point_features]
    if num_point_features is not None and pts.shape[1] != num_point_features:
        raise DatasetError(
            f"{path}: points have {pts.shape[1]} columns but the model expects "
            f"num_point_features={num_point_features}; set model.num_point_features: "
            f"{pts.shape[1]} in the config (or fix the data)"
        )
    pts = pts.astype(np.float32, copy=False)
    if not np.all(np.isfinite(pts)):
        raise DatasetError(f"{path}: points contain NaN or inf")
    return pts


def read_labels(path: str | Path) -> tuple[np.ndarray, tuple[str, ...]]:
    """Parse ``labels/<id>.txt`` into (M, 7) float32 boxes and M class names."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: label file missing (expected labels/<frame_id>.txt)")
    boxes, names = [], []
    for lineno, line in enumerate(path.read_text().splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        if len(fields) != 8:
            raise DatasetError(
                f"{path}:{lineno}: expected 8 fields 'x y z dx dy dz heading class_name', got "
                f"{len(fields)}: {line.strip()!r}"
            )
        try:
            values = [float(v) for v in fields[:7]]
        except ValueError as exc:
            raise DatasetError(f"{path}:{lineno}: non-numeric box value ({exc})") from exc
        if not np.all(np.isfinite(values)):
            raise DatasetError(f"{path}:{lineno}: box contains NaN or inf")
        if min(values[3:6]) <= 0:
            raise DatasetError(f"{path}:{lineno}: box sizes dx dy dz must be > 0, got {values[3:6]}")
        boxes.append(values)
        names.append(fields[7])
    return np.asarray(boxes, dtype=np.float32).reshape(-1, 7), tuple(names)


class OpenPCDetDataset:
    """A dataset folder in OpenPCDet's custom layout.

    Parameters
    ----------
    root : dataset folder (``points/``, ``labels/``, ``ImageSets/``).
    num_point_features : if given, every point file must have this many columns.
    drop_extra_columns : keep the first ``num_point_features`` columns of files that have more
        (e.g. a 5th Doppler column), instead of refusing them.
    """

    def __init__(self, root: str | Path, num_point_features: int | None = None,
                 drop_extra_columns: bool = False) -> None:
        self.root = Path(root)
        self.num_point_features = num_point_features
        self.drop_extra_columns = drop_extra_columns
        if not self.root.is_dir():
            raise DatasetError(f"dataset folder {self.root} does not exist (set data.root)")
        for sub in ("points", "labels", "ImageSets"):
            if not (self.root / sub).is_dir():
                raise DatasetError(
                    f"{self.root}: missing sub-folder {sub}/ — an OpenPCDet custom dataset has "
                    "points/*.npy, labels/*.txt and ImageSets/{train,val,test}.txt"
                )

    def splits(self) -> list[str]:
        """Names of the split files in ``ImageSets/``."""
        return sorted(p.stem for p in (self.root / "ImageSets").glob("*.txt"))

    def split_ids(self, split: str) -> list[str]:
        """Frame ids listed in ``ImageSets/<split>.txt`` (order kept, duplicates rejected)."""
        path = self.root / "ImageSets" / f"{split}.txt"
        if not path.is_file():
            raise DatasetError(f"{path}: split file missing; available splits: {self.splits()}")
        ids = [s.strip() for s in path.read_text().splitlines() if s.strip()]
        dup = {i for i in ids if ids.count(i) > 1}
        if dup:
            raise DatasetError(f"{path}: duplicate frame ids {sorted(dup)[:5]}")
        return ids

    def frame(self, frame_id: str) -> Frame:
        """Load one frame."""
        pts = read_points(self.root / "points" / f"{frame_id}.npy", self.num_point_features,
                          self.drop_extra_columns)
        boxes, names = read_labels(self.root / "labels" / f"{frame_id}.txt")
        return Frame(frame_id, pts, boxes, names)

    def frames(self, ids: Iterable[str]) -> list[Frame]:
        """Load several frames (all in memory: radar frames are ~2,000 points)."""
        return [self.frame(i) for i in ids]

    def __repr__(self) -> str:
        return f"OpenPCDetDataset({str(self.root)!r}, splits={self.splits()})"


def write_frame(root: str | Path, frame: Frame) -> None:
    """Write ``points/<id>.npy`` (float32) and ``labels/<id>.txt`` atomically."""
    root = Path(root)
    (root / "points").mkdir(parents=True, exist_ok=True)
    (root / "labels").mkdir(parents=True, exist_ok=True)
    pts = np.ascontiguousarray(frame.points, dtype=np.float32)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise DatasetError(f"frame {frame.frame_id}: points must be (N, C>=3), got {pts.shape}")
    boxes = np.asarray(frame.boxes, dtype=np.float64).reshape(-1, 7)
    if len(frame.names) != boxes.shape[0]:
        raise DatasetError(f"frame {frame.frame_id}: {boxes.shape[0]} boxes but "
                           f"{len(frame.names)} names")
    if any(not n or any(c.isspace() for c in n) for n in frame.names):
        raise DatasetError(f"frame {frame.frame_id}: class names must be non-empty, no spaces")
    import io

    buf = io.BytesIO()
    np.save(buf, pts, allow_pickle=False)
    atomic_write(root / "points" / f"{frame.frame_id}.npy", buf.getvalue())
    lines = [" ".join(f"{v:.6f}" for v in b) + f" {n}\n"
             for b, n in zip(boxes, frame.names, strict=True)]
    atomic_write(root / "labels" / f"{frame.frame_id}.txt", "".join(lines).encode())


def write_split(root: str | Path, split: str, ids: Sequence[str]) -> None:
    """Write ``ImageSets/<split>.txt``."""
    d = Path(root) / "ImageSets"
    d.mkdir(parents=True, exist_ok=True)
    atomic_write(d / f"{split}.txt", "".join(f"{i}\n" for i in ids).encode())


def write_dataset(
    root: str | Path, frames: Iterable[Frame], splits: Mapping[str, Sequence[str]]
) -> OpenPCDetDataset:
    """Write frames and split files; every split id must be one of the written frames.

    The folder then holds exactly this dataset: ``points/*.npy`` and ``labels/*.txt`` of frames
    not written now (left by an earlier, larger export into the same folder) and split files
    not given are removed (logged), so no stale frame lies next to the splits; so are the
    temporary files of an export killed mid-write. Other files in the folder are left alone.
    """
    root = Path(root)
    for sub in ("points", "labels", "ImageSets"):  # an export of no frame is still a dataset
        (root / sub).mkdir(parents=True, exist_ok=True)
    written = set()
    for f in frames:
        write_frame(root, f)
        written.add(f.frame_id)
    for name, ids in splits.items():
        unknown = [i for i in ids if i not in written]
        if unknown:
            raise DatasetError(f"split {name!r} lists frames that were not written: {unknown[:5]}")
        write_split(root, name, ids)
    stale = [p for sub, suffix in (("points", ".npy"), ("labels", ".txt"))
             for p in sorted((root / sub).glob(f"*{suffix}")) if p.stem not in written]
    stale += [p for p in sorted((root / "ImageSets").glob("*.txt")) if p.stem not in splits]
    stale += [p for sub in ("points", "labels", "ImageSets", ".")
              for p in abandoned_temp_files(root / sub)]  # an export killed mid-write
    for p in stale:
        p.unlink()
    if stale:
        log.warning("%s: removed %d stale file(s) of an earlier export (e.g. %s)", root,
                    len(stale), stale[0].relative_to(root))
    return OpenPCDetDataset(root)


def write_metadata(root: str | Path, metadata: Mapping) -> Path:
    """Write ``ROOT/dataset.json`` atomically (keys sorted); returns its path."""
    return write_json(Path(root) / METADATA_FILE, dict(metadata), sort_keys=True)


def read_metadata(root: str | Path) -> dict:
    """``ROOT/dataset.json`` as a dict, its ``domain`` :data:`UNDECLARED` when the file (or the
    key) is missing — a measured dataset such as IFR declares ``{"domain": "measured"}`` to be
    called so. A malformed file raises :class:`DatasetError` naming it."""
    import json

    path = Path(root) / METADATA_FILE
    if not path.is_file():
        return {"domain": UNDECLARED}
    try:
        doc = json.loads(path.read_text())
    except (ValueError, OSError) as exc:
        raise DatasetError(f"{path}: not valid JSON ({exc}); fix or delete the file") from exc
    if not isinstance(doc, dict):
        raise DatasetError(f"{path}: expected a JSON object")
    if doc.get("domain") in (None, ""):
        doc["domain"] = UNDECLARED
    return doc
