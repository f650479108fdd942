"""The experiment's datasets: identity (content digest), domain label, splits, frames.

A sweep works on any datasets in OpenPCDet's custom layout: a simulated one (pre-training), a
"real" one (fine-tuning and test) and, for the ablations, more simulated ones. Each is
identified by a digest of its content (:func:`dataset_digest`), which enters every training
run's content key, so rerunning a sweep on changed data recomputes what the change touches.
Its ``dataset.json`` (:func:`sim2radar.datasets.read_metadata`) says which domain it is; a
folder without one, or whose file declares no ``domain``, is ``"undeclared"`` — never guessed
"measured": the report calls a real domain measured radar only where it is declared so.

Intensity matching (paper §6.1) is fitted per fine-tuning run, on that run's real subset only
(:func:`fit_subset_intensity_match`): a sim-pretrain arm at 5 % must not see the intensity
distribution of more real frames than it trains on.

A proxy "real" domain (the reference radar) must not share worlds with the simulated domain —
the transfer experiment would then test on scenes the encoder was pre-trained on
(:func:`check_disjoint_worlds`). Whatever the domains, a simulated dataset that *is* the real
one, or holds any frame whose points equal a real validation or test frame's, is refused
(:func:`check_no_shared_frames`): pre-training would see the frames the sweep evaluates on.
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from sim2radar.datasets import UNDECLARED, DatasetError, Frame, OpenPCDetDataset, read_metadata
from sim2radar.experiment.plan import ids_digest
from sim2radar.radar.intensity import IntensityMatch, fit_intensity_match

__all__ = [
    "UNDECLARED",
    "DomainDataset",
    "SubsetIntensityMatch",
    "open_domain",
    "dataset_digest",
    "world_of_frame",
    "check_disjoint_worlds",
    "check_no_shared_frames",
    "check_not_the_same",
    "points_digest",
    "fit_subset_intensity_match",
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
    metadata : dict — its ``dataset.json`` (``{}`` without one; no ``domain`` key where the
        file declares none).
    splits : dict[str, list[str]] — frame ids per split file.
    """

    role: str
    root: Path
    key: str
    metadata: dict
    splits: dict[str, list[str]]

    @property
    def domain(self) -> str:
        """The declared ``domain`` of its ``dataset.json``, else :data:`UNDECLARED`."""
        d = self.metadata.get("domain")
        return d if isinstance(d, str) and d.strip() else UNDECLARED

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
        intensity of files that also carry Doppler) and boxes of ``class_names``.

        Raises
        ------
        DatasetError — a label whose class differs from one of ``class_names`` only in case
        (``Door`` for ``door``: it would be dropped silently and every run would train on no
        box), naming the file, the label and the classes.
        """
        ds = OpenPCDetDataset(self.root, num_point_features, drop_extra_columns=True)
        frames = ds.frames(ids)
        wanted = {c.lower(): c for c in class_names}
        for f in frames:
            for name in f.names:
                if name not in class_names and name.lower() in wanted:
                    raise DatasetError(
                        f"{self.root}/labels/{f.frame_id}.txt: label class {name!r} is not "
                        f"{wanted[name.lower()]!r}: the detector's classes {list(class_names)} "
                        "match exactly; rename the labels (sim2radar import matches classes "
                        "without case)")
        return [f.select(class_names) for f in frames]

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
    metadata = read_metadata(root)  # validates the file; "undeclared" unless it declares one
    return DomainDataset(role, root.resolve(), dataset_digest(root), metadata, splits)


def world_of_frame(frame_id: str) -> str | None:
    """``world_000007`` for ``world_000007_f002`` (procedural frames); None for other ids."""
    m = _WORLD_RE.match(frame_id)
    return m.group(1) if m else None


def check_disjoint_worlds(sim: DomainDataset, real: DomainDataset) -> None:
    """Refuse a proxy real domain that shares procedural worlds with a simulated one (the
    sweep would test on scenes it pre-trained on). Only a proxy real domain is checked
    (measured, undeclared and other declared domains are not)."""
    if not real.is_proxy:
        return
    shared = ({world_of_frame(i) for i in sim.ids()} & {world_of_frame(i) for i in real.ids()})
    shared.discard(None)
    if shared:
        raise DatasetError(
            f"{real.root} ({real.domain}) and {sim.root} share {len(shared)} world(s), e.g. "
            f"{sorted(shared)[:3]}: build the reference dataset from other world seeds "
            "(`sim2radar reference --first-seed ...`)")


def points_digest(points: np.ndarray) -> str:
    """SHA-256 of a frame's point positions (x y z as float32, row order kept): equal for the
    same frame whatever extra columns (intensity, Doppler) or file it was saved with."""
    xyz = np.ascontiguousarray(np.asarray(points)[:, :3], dtype=np.float32)
    return hashlib.sha256(np.asarray(xyz.shape).tobytes() + xyz.tobytes()).hexdigest()


def check_not_the_same(sim: DomainDataset, real: DomainDataset) -> None:
    """Refuse a simulated dataset that is the real one (same folder or same content)."""
    if sim.root == real.root or sim.key == real.key:
        same = "is" if sim.root == real.root else "has the same content as"
        raise DatasetError(
            f"the {sim.role} dataset {sim.root} {same} the real dataset {real.root}: "
            "pre-training would see the real test frames; give a simulated dataset "
            "(sim2radar generate --export-openpcdet ...) as SIM")


def check_no_shared_frames(sim: DomainDataset, real: DomainDataset,
                           sim_frames: Sequence[Frame], held_out: Sequence[Frame]) -> None:
    """Refuse a simulated dataset that is the real one (same folder or same content) or that
    holds a frame whose points equal one of the real dataset's held-out frames (``held_out``:
    its validation and test frames) — pre-training on it would see what the sweep evaluates.

    Raises
    ------
    DatasetError — naming both folders, an example frame pair and the fix.
    """
    check_not_the_same(sim, real)
    held = {points_digest(f.points): f.frame_id for f in held_out if len(f.points)}
    shared = [(f.frame_id, held[d]) for f in sim_frames if len(f.points)
              and (d := points_digest(f.points)) in held]
    if shared:
        a, b = shared[0]
        raise DatasetError(
            f"the {sim.role} dataset {sim.root} shares {len(shared)} frame(s) with the "
            f"validation/test splits of {real.root} (same points), e.g. {sim.role} {a} = real "
            f"{b}: pre-training would see frames the sweep evaluates on; remove them from the "
            f"{sim.role} dataset or build it from other worlds")


@dataclasses.dataclass(frozen=True)
class SubsetIntensityMatch:
    """An intensity match fitted on one run's real fine-tuning subset.

    Attributes
    ----------
    match : IntensityMatch — sim -> real quantile map of intensities [dB].
    subset_ids : tuple of str — the real frames whose intensities it was fitted on.
    n_sim_frames : int — simulated frames it was fitted on.
    """

    match: IntensityMatch
    subset_ids: tuple[str, ...]
    n_sim_frames: int

    def to_dict(self) -> dict:
        """:meth:`IntensityMatch.to_dict` plus what it was fitted on (for provenance and the
        pre-training's content key): ``fitted_on`` (one line), ``subset_ids_digest``
        (:func:`~sim2radar.experiment.plan.ids_digest` of the subset, in order),
        ``n_real_frames``, ``n_sim_frames``."""
        return {**self.match.to_dict(),
                "fitted_on": f"{len(self.subset_ids)} frames of the run's real fine-tuning "
                             "subset",
                "subset_ids_digest": ids_digest(self.subset_ids),
                "n_real_frames": len(self.subset_ids), "n_sim_frames": int(self.n_sim_frames)}


def _intensities(frames: Sequence[Frame], what: str) -> np.ndarray:
    cols = [np.asarray(f.points)[:, 3] for f in frames
            if np.asarray(f.points).ndim == 2 and np.asarray(f.points).shape[1] > 3]
    if not cols:
        raise ValueError(f"intensity matching: the {what} frames have no intensity column")
    return np.concatenate(cols)


def fit_subset_intensity_match(sim_frames: Sequence[Frame], real_frames: Sequence[Frame],
                               subset_ids: Sequence[str], *,
                               n_quantiles: int = 256) -> SubsetIntensityMatch:
    """Log-space histogram matching (:func:`sim2radar.radar.intensity.fit_intensity_match`,
    paper §6.1) of ``sim_frames`` onto the intensities of the real frames in ``subset_ids``
    only: the real fine-tuning subset of one (trial, fraction) run.

    Parameters
    ----------
    sim_frames : simulated frames (column 3: intensity [dB]) — all that pre-training uses.
    real_frames : real frames containing at least the subset (e.g. the whole train split);
        frames outside ``subset_ids`` are ignored.
    subset_ids : the run's real train ids (:attr:`~sim2radar.experiment.plan.RunSpec
        .train_ids`).
    n_quantiles : quantiles of the map.

    Raises
    ------
    ValueError — an empty subset, a subset id not among ``real_frames`` (named), frames
    without an intensity column.
    """
    ids = tuple(str(i) for i in subset_ids)
    if not ids:
        raise ValueError("intensity matching: the real subset is empty")
    by_id = {f.frame_id: f for f in real_frames}
    missing = [i for i in ids if i not in by_id]
    if missing:
        raise ValueError(f"intensity matching: {len(missing)} subset frame(s) not among the "
                         f"real frames given, e.g. {missing[:3]}")
    subset = [by_id[i] for i in dict.fromkeys(ids)]
    match = fit_intensity_match(_intensities(sim_frames, "sim"),
                                _intensities(subset, "real subset"), n_quantiles)
    return SubsetIntensityMatch(match, ids, len(sim_frames))


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
