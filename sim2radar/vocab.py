"""The project's shared vocabularies: semantic classes, material classes, box layout.

Every stage (worlds, reconstruction, VLM labelling, radar, detector) speaks these names. Integer
ids in masks and Parquet columns are indices into these tuples, so append-only.
"""

from __future__ import annotations

from typing import Literal, get_args

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
Status = Literal["ok", "skipped", "failed"]
STATUSES: tuple[str, ...] = get_args(Status)


#: The longest scene or frame id (a file name holds a frame id and a suffix; file systems stop
#: at 255 bytes).
MAX_ID_LENGTH = 120


def id_problem(name: str) -> str | None:
    """Why ``name`` cannot be a scene or frame id (None when it can): ids become file names
    and lines of OpenPCDet's ``ImageSets/*.txt``, so they must be printable (no newline, tab or
    other control character), hold no path separator, not be ``.`` / ``..`` and be at most
    :data:`MAX_ID_LENGTH` characters. Spaces and non-ASCII letters are fine."""
    if not isinstance(name, str) or not name.strip():
        return "an id must not be empty or blank"
    if not name.isprintable():
        return "an id must be printable: no newline, tab or other control character"
    if "/" in name or "\\" in name or name in (".", ".."):
        return "an id must not hold a path separator or be '.' / '..'"
    if name != name.strip():
        return "an id must not start or end with whitespace"
    if len(name) > MAX_ID_LENGTH:
        return f"an id must be at most {MAX_ID_LENGTH} characters, this one has {len(name)}"
    return None
