"""The reference ("proxy-real") dataset: which worlds, how many frames, which split.

The experiment needs a "real" radar domain. Without measured data, the project builds one with
the reference radar — the signal-level FMCW MIMO simulator (preset ``ti-mmwcas-reference``) on
the procedural worlds' *ground-truth* geometry over the radar's full field of view — from
worlds **disjoint** from the simulated (pre-training) domain's. It is always labelled as a proxy
(:data:`DOMAIN_LABEL`); a measured dataset in OpenPCDet's custom layout replaces it with no code
change.

Splits are by world, so no scene leaks from train into test. By default the dataset is sized
like the paper's IFR subset (:data:`PAPER_SPLIT_FRAMES`: 371 / 92 / 155 frames — the paper
says 617 in all, its splits add up to 618): each split
gets ``ceil(n / frames_per_world)`` worlds of ``frames_per_world`` frames, its last world only
the remainder. With an explicit number of worlds, every world has ``frames_per_world`` frames
and the worlds are split in the paper's proportions.
"""

from __future__ import annotations

import dataclasses
import math

from sim2radar.datasets.splits import split_groups

__all__ = [
    "DOMAIN_LABEL",
    "stored_dataset_domain",
    "PAPER_SPLIT_FRAMES",
    "REFERENCE_FIRST_SEED",
    "ReferencePlan",
    "plan_reference",
]

#: How every reference dataset, its frames and every result on it are labelled.
DOMAIN_LABEL = "proxy-real (reference radar simulation)"
#: The paper's IFR split sizes (frames): 371 train / 92 val / 155 test (618 in all; the paper's
#: text says 617).
PAPER_SPLIT_FRAMES: dict[str, int] = {"train": 371, "val": 92, "test": 155}
#: First world seed of reference datasets by default: far from the factory's default worlds
#: (0, 1, ...) so the two domains do not share worlds.
REFERENCE_FIRST_SEED = 100_000


@dataclasses.dataclass(frozen=True)
class ReferencePlan:
    """Worlds of a reference dataset.

    Attributes
    ----------
    seeds : tuple[int, ...] — world seeds, in order.
    frames_by_seed : dict[int, int] — frames of each world.
    splits : dict[str, list[int]] — split name -> world seeds.
    """

    seeds: tuple[int, ...]
    frames_by_seed: dict[int, int]
    splits: dict[str, list[int]]

    @property
    def n_frames(self) -> int:
        return int(sum(self.frames_by_seed.values()))

    def split_frames(self) -> dict[str, int]:
        """Frames per split."""
        return {k: int(sum(self.frames_by_seed[s] for s in v)) for k, v in self.splits.items()}


def stored_dataset_domain(fidelity: str, geometry: str) -> str:
    """The domain of frames already in a store, from their radar fidelity and geometry: the
    signal-level radar on ground-truth geometry is the reference radar (:data:`DOMAIN_LABEL`,
    a proxy for measured radar); anything else is simulated."""
    if fidelity == "signal" and geometry == "ground_truth":
        return DOMAIN_LABEL
    return f"simulated ({fidelity} radar, {geometry} geometry)"


def plan_reference(
    first_seed: int = REFERENCE_FIRST_SEED,
    *,
    worlds: int | None = None,
    frames_per_world: int = 10,
    split_frames: dict[str, int] | None = None,
    seed: int = 0,
) -> ReferencePlan:
    """Worlds, frames and splits of a reference dataset (see the module docstring).

    Parameters
    ----------
    first_seed : int >= 0 — seed of the first world; worlds are consecutive seeds.
    worlds : int, optional — number of worlds (each ``frames_per_world`` frames, split by world
        in the proportions of ``split_frames``); None = sized like ``split_frames`` exactly.
    frames_per_world : int >= 1
    split_frames : dict — split name -> frames (default :data:`PAPER_SPLIT_FRAMES`).
    seed : int — shuffles worlds into splits when ``worlds`` is given.
    """
    sizes = dict(split_frames or PAPER_SPLIT_FRAMES)
    if int(first_seed) < 0:
        raise ValueError(f"first_seed must be >= 0, got {first_seed}")
    if int(frames_per_world) < 1:
        raise ValueError(f"frames_per_world must be >= 1, got {frames_per_world}")
    if not sizes or any(int(n) < 0 for n in sizes.values()) or sum(sizes.values()) < 1:
        raise ValueError(f"split_frames must give non-negative frame counts, got {sizes}")
    fpw = int(frames_per_world)
    if worlds is None:
        seeds, frames, splits = [], {}, {}
        s = int(first_seed)
        for name, n in sizes.items():
            splits[name] = []
            for k in range(math.ceil(int(n) / fpw)):
                frames[s] = min(fpw, int(n) - k * fpw)
                splits[name].append(s)
                seeds.append(s)
                s += 1
        return ReferencePlan(tuple(seeds), frames, splits)
    if int(worlds) < 1:
        raise ValueError(f"worlds must be >= 1, got {worlds}")
    seeds = list(range(int(first_seed), int(first_seed) + int(worlds)))
    total = float(sum(sizes.values()))
    names = list(sizes)
    if len(names) != 3:
        raise ValueError("with an explicit number of worlds, split_frames needs exactly three "
                         f"splits (train, val, test), got {names}")
    fractions = tuple(sizes[n] / total for n in names)
    by_id = split_groups([str(s) for s in seeds], seed, fractions)  # type: ignore[arg-type]
    splits = {new: sorted(int(s) for s in by_id[old])
              for new, old in zip(names, ("train", "val", "test"), strict=True)}
    return ReferencePlan(tuple(seeds), {s: fpw for s in seeds}, splits)
