"""Radar datasets on disk: OpenPCDet's custom layout (IFR) and synthetic door frames."""

from sim2radar.datasets.openpcdet import (
    METADATA_FILE,
    UNDECLARED,
    DatasetError,
    Frame,
    OpenPCDetDataset,
    read_labels,
    read_metadata,
    read_points,
    write_dataset,
    write_frame,
    write_metadata,
    write_split,
)
from sim2radar.datasets.splits import split_groups
from sim2radar.datasets.synthetic import make_door_frames, write_synthetic_dataset

__all__ = [
    "METADATA_FILE",
    "UNDECLARED",
    "DatasetError",
    "Frame",
    "OpenPCDetDataset",
    "make_door_frames",
    "read_labels",
    "read_metadata",
    "read_points",
    "split_groups",
    "write_dataset",
    "write_frame",
    "write_metadata",
    "write_split",
    "write_synthetic_dataset",
]
