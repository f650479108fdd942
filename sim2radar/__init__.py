"""sim2radar — a dataset factory for mmWave radar perception.

Stages, one sub-package each, in the order data flows through them::

    worlds/       procedural indoor worlds (RGB, depth, masks, LiDAR, door boxes)
    reconstruct/  RGB [+ LiDAR] -> material-labelled meshes + door boxes
    em/           ITU-R P.2040 materials and Fresnel reflection
    radar/        Mitsuba ray tracing -> range/azimuth/elevation cube -> radar points
    detect/       PointPillars (pure PyTorch), training, encoder transfer
    evaluate/     KITTI-protocol AP, reconstruction and sim-real gap metrics
    datasets/     measured radar datasets (OpenPCDet custom layout)

The library is pure computation: no Prefect, no hidden I/O. Orchestration lives in the
sibling packages ``tasks`` (Prefect tasks), ``flows`` (Prefect flows) and ``storage``
(the Parquet artifact store).
"""

from sim2radar.mesh import MaterialMesh, load_mesh, load_scene

__version__ = "0.1.0"

__all__ = ["MaterialMesh", "load_mesh", "load_scene", "__version__"]
