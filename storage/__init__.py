"""The Parquet artifact store: declared schemas, content keys, atomic publish, provenance,
per-dataset manifests. Local folder by default; any fsspec URI (``s3://``, ``gs://``,
``memory://``) works the same.

Typical use by a stage::

    from sim2radar.storage import ArtifactStore, content_key

    store = ArtifactStore("out/store")
    key = content_key(stage="radar_points", stage_version=1,
                      inputs={"scene": scene_key}, config=radar.to_dict())
    if not store.exists("radar_points", key):
        store.write("radar_points", key, table, stage_version=1,
                    provenance={"inputs": {"scene": scene_key}, "config": radar.to_dict(),
                                "seed": 0, "timings_s": {"simulate": 0.4}})
    table = store.read("radar_points", key)            # validated against storage/schemas.py
    store.manifest("demo").upsert("corridor", "ok", artifacts={"radar_points": key})

Schemas are declared once in :mod:`sim2radar.storage.schemas` (other stages append blocks there); array
columns are built with :mod:`sim2radar.storage.codecs`. This package never imports Prefect.
"""

from sim2radar.storage.codecs import (
    RadarPointsFrame,
    fixed_rows,
    fixed_rows_column,
    meshes_from_table,
    meshes_to_table,
    radar_frames_from_table,
    radar_frames_to_table,
    ragged_arrays,
    ragged_column,
)
from sim2radar.storage.keys import (
    KEY_LENGTH,
    bytes_digest,
    canonical_json,
    content_key,
    file_digest,
)
from sim2radar.storage.manifest import STATUSES, Manifest
from sim2radar.storage.provenance import (
    PROVENANCE_KEY,
    build_provenance,
    combine_provisional,
    model_file_hashes,
    package_versions,
)
from sim2radar.storage.schemas import (
    ArtifactSchema,
    SchemaError,
    field,
    get_schema,
    register_schema,
    schema_names,
)
from sim2radar.storage.store import (
    ArtifactNotFoundError,
    ArtifactStore,
    check_writable,
    is_transient_io_error,
)

__all__ = [
    "ArtifactStore",
    "ArtifactNotFoundError",
    "check_writable",
    "is_transient_io_error",
    "ArtifactSchema",
    "SchemaError",
    "Manifest",
    "STATUSES",
    "KEY_LENGTH",
    "content_key",
    "canonical_json",
    "bytes_digest",
    "file_digest",
    "field",
    "get_schema",
    "register_schema",
    "schema_names",
    "PROVENANCE_KEY",
    "build_provenance",
    "combine_provisional",
    "model_file_hashes",
    "package_versions",
    "ragged_column",
    "ragged_arrays",
    "fixed_rows_column",
    "fixed_rows",
    "meshes_to_table",
    "meshes_from_table",
    "radar_frames_to_table",
    "radar_frames_from_table",
    "RadarPointsFrame",
]
