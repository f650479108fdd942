"""Whether a Parquet file's bytes are whole: the checks behind the store's self-healing.

:func:`file_problem` says what keeps a file from reading (footer, row groups, page CRCs, the
recorded schema); :func:`is_corrupt_file_error` tells a damaged file (Arrow's invalid-data
errors, a failed page checksum) from an I/O error that a retry may cure.
"""

from __future__ import annotations

import pyarrow as pa
import pyarrow.parquet as pq

__all__ = ["SCHEMA_KEY", "file_problem", "is_corrupt_file_error"]

#: Parquet key-value metadata key holding ``"<stage>:<schema version>"``.
SCHEMA_KEY = b"sim2radar.schema"


def file_problem(fs, path: str, *, deep: bool = False,
                 expected_schema: str | None = None) -> str | None:
    """What keeps the Parquet file at ``path`` from reading (None when nothing does): the
    footer must parse and its row groups add up to its row count; ``deep`` also decodes every
    page and, with ``expected_schema`` (a stage name), checks the recorded schema's stage."""
    try:
        with fs.open(path, "rb") as fh:
            pf = pq.ParquetFile(fh, page_checksum_verification=True)
            meta = pf.metadata
            if sum(meta.row_group(i).num_rows for i in range(meta.num_row_groups)) \
                    != meta.num_rows:
                return "its row groups do not add up to its row count"
            if deep:
                pf.read(use_threads=False)  # a check, not a load: no Arrow thread pool
                recorded = (pf.schema_arrow.metadata or {}).get(SCHEMA_KEY, b"").decode()
                if expected_schema and recorded.split(":")[0] != expected_schema:
                    return f"it records schema {recorded or '(none)'!r}, not {expected_schema!r}"
    except Exception as exc:
        if not is_corrupt_file_error(exc):
            raise
        return f"not a readable Parquet file: {' '.join(str(exc).split())}"
    return None


def is_corrupt_file_error(exc: BaseException) -> bool:
    """True if ``exc``, raised while parsing or decoding a Parquet file, says the file's bytes
    are wrong (Arrow's invalid-data errors, an unexpected end of file, a page checksum that
    fails — Arrow raises that as an ``OSError`` without an errno) rather than that the file
    could not be read (a missing file, a permission error, a timeout, a dropped connection)."""
    if isinstance(exc, pa.ArrowException | EOFError):
        return not isinstance(exc, FileNotFoundError | PermissionError)
    return (isinstance(exc, OSError) and exc.errno is None
            and not isinstance(exc, ConnectionError | TimeoutError))
