"""The project's shared vocabularies: semantic classes, material classes, box layout.

Every stage (worlds, reconstruction, VLM labelling, radar, detector) speaks these names. Integer
ids in masks and Parquet columns are indices into these tuples, so append-only.
"""

from __future__ import annotations

#: Semantic classes. Index 0 means "no label / no surface". The middle block is the paper's
#: Grounding DINO prompt ("door, wall, floor, ceiling, window, fire extinguisher, handrail");
#: ``clutter`` covers cabinets, radiators, bins and other furniture.
SEMANTIC_CLASSES: tuple[str, ...] = (
    "unknown",
    "wall",
    "floor",
    "ceiling",
    "door",
    "window",
    "fire_extinguisher",
    "handrail",
    "clutter",
)

#: The paper's material classes (§3 Stage 3), as asked of the VLM. Index 0 is ``unknown``.
MATERIAL_CLASSES: tuple[str, ...] = (
    "unknown",
    "metal",
    "glass",
    "wood",
    "plasterboard",
    "ceramic_tile",
    "concrete",
    "fabric",
    "plastic",
)

#: The Grounding DINO text prompt of the paper.
DETECTION_PROMPT = "door, wall, floor, ceiling, window, fire extinguisher, handrail"

#: Column names of a 3D box row: centre x, y, z [m], size dx (along heading), dy, dz [m],
#: heading [rad] about +z. OpenPCDet/KITTI-LiDAR convention; z is the box centre.
BOX_FIELDS: tuple[str, ...] = ("x", "y", "z", "dx", "dy", "dz", "heading")


def semantic_id(name: str) -> int:
    """Index of a semantic class; raises ``ValueError`` listing the known names."""
    try:
        return SEMANTIC_CLASSES.index(name)
    except ValueError:
        raise ValueError(f"unknown semantic class {name!r}; known: {SEMANTIC_CLASSES}") from None


def material_id(name: str) -> int:
    """Index of a material class; raises ``ValueError`` listing the known names."""
    try:
        return MATERIAL_CLASSES.index(name)
    except ValueError:
        raise ValueError(f"unknown material class {name!r}; known: {MATERIAL_CLASSES}") from None

#: What became of one unit of work (a manifest row, a sweep's run): computed, found cached
#: (nothing recomputed) or failed with its error.
STATUSES: tuple[str, ...] = ("ok", "skipped", "failed")
