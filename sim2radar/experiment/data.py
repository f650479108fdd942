"""The experiment's datasets: identity (content digest), domain label, splits, frames.

A sweep works on any datasets in OpenPCDet's custom layout: a simulated one (pre-training), a
"real" one (fine-tuning and test) and, for the ablations, more simulated ones. Each is
identified by a digest of its content (:func:`dataset_digest`), which enters every training
run's content key, so rerunning a sweep on changed data recomputes what the change touches.
Its ``dataset.json`` (:func:`sim2radar.datasets.read_metadata`) says which domain it is; a
folder without one is a measured dataset.

A proxy "real" domain (the reference radar) must not share worlds with the simulated domain —
the transfer experiment would then test on scenes the encoder was pre-trained on
(:func:`check_disjoint_worlds`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from sim2radar.datasets import DatasetError, Frame, OpenPCDetDataset, read_metadata

__all__ = [
    "DomainDataset",
    "open_domain",
    "dataset_digest",
    "world_of_frame",
    "check_disjoint_worlds",
    "with_intensity",
]

_WORLD_RE = re.compile(r"^(world_\d+)_f\d+$")


def dataset_digest(root: str | Path) -> str:
    """SHA-256 (hex, 20 characters) of a dataset folder's content: the split files and every
    point and label file (names and bytes), in sorted order. ``dataset.json`` is left out (its
    export time changes without the data changing)."""
    root = Path(root)
    h = hashlib.sha256()
    for sub, pattern in (("ImageSets", "*.txt"), ("labels", "*.txt"), ("points", "*.npy")):
        for path in sorted((root / sub).glob(pattern)):
            h.update(f"{sub}/{path.name}\0".encode())
            h.update(hashlib.sha256(path.read_bytes()).digest())
    return h.hexdigest()[:20]


@dataclasses.dataclass(frozen=True)
class DomainDataset:
    """One dataset of a sweep.

    Attributes
    ----------
    role : str — ``sim``, ``real``, ``sim-gt`` or ``sim-one-material``.
    root : Path — the folder (OpenPCDet custom layout).
    key : str — :func:`dataset_digest` of the folder.
    metadata : dict — its ``dataset.json`` (``{"domain": "measured"}`` without one).
    splits : dict[str, list[str]] — frame ids per split file.
    """

    role: str
    root: Path
    key: str
    metadata: dict
    splits: dict[str, list[str]]

    @property
    def domain(self) -> str:
        return str(self.metadata.get("domain", "measured"))

    @property
    def is_proxy(self) -> bool:
        """True for a labelled stand-in for measured radar (the reference radar)."""
        return self.domain.startswith("proxy")

    def ids(self, splits: Sequence[str] | None = None) -> list[str]:
        """Frame ids of the given splits (all splits when None), in split order."""
        names = list(self.splits) if splits is None else list(splits)
        out: list[str] = []
        for name in names:
            out += self.splits.get(name, [])
        return list(dict.fromkeys(out))

    def frames(self, ids: Sequence[str], num_point_features: int,
               class_names: Sequence[str]) -> list[Frame]:
        """Load frames, keeping the first ``num_point_features`` point columns (x y z
        intensity of files that also carry Doppler) and boxes of ``class_names``."""
        ds = OpenPCDetDataset(self.root, num_point_features, drop_extra_columns=True)
        return [f.select(class_names) for f in ds.frames(ids)]

    def describe(self) -> dict:
        """JSON-able summary for provenance and the dashboard."""
        return {"role": self.role, "path": str(self.root), "key": self.key,
                "domain": self.domain, "n_frames": len(self.ids()),
                "splits": {k: len(v) for k, v in self.splits.items()},
                "metadata": self.metadata}


def open_domain(root: str | Path, role: str) -> DomainDataset:
    """Open a dataset folder for a sweep; raises :class:`~sim2radar.datasets.DatasetError`
    naming the file at fault."""
    root = Path(root)
    ds = OpenPCDetDataset(root)
    splits = {name: ds.split_ids(name) for name in ds.splits()}
    if not any(splits.values()):
        raise DatasetError(f"{root}/ImageSets: no split lists any frame")
    return DomainDataset(role, root.resolve(), dataset_digest(root), read_metadata(root), splits)


def world_of_frame(frame_id: str) -> str | None:
    """``world_000007`` for ``world_000007_f002`` (procedural frames); None for other ids."""
    m = _WORLD_RE.match(frame_id)
    return m.group(1) if m else None


def check_disjoint_worlds(sim: DomainDataset, real: DomainDataset) -> None:
    """Refuse a proxy real domain that shares procedural worlds with a simulated one (the
    sweep would test on scenes it pre-trained on). Measured datasets are not checked."""
    if not real.is_proxy:
        return
    shared = ({world_of_frame(i) for i in sim.ids()} & {world_of_frame(i) for i in real.ids()})
    shared.discard(None)
    if shared:
        raise DatasetError(
            f"{real.root} ({real.domain}) and {sim.root} share {len(shared)} world(s), e.g. "
            f"{sorted(shared)[:3]}: build the reference dataset from other world seeds "
            "(`sim2radar reference --first-seed ...`)")


def with_intensity(frames: Sequence[Frame], mapping) -> list[Frame]:
    """The frames with column 3 (intensity [dB]) passed through ``mapping.apply``
    (:class:`sim2radar.radar.intensity.IntensityMatch`)."""
    out = []
    for f in frames:
        pts = np.array(f.points, dtype=np.float32, copy=True)
        if len(pts) and pts.shape[1] > 3:
            pts[:, 3] = mapping.apply(pts[:, 3])
        out.append(Frame(f.frame_id, pts, f.boxes, f.names))
    return out
