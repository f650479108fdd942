"""The Parquet artifact store: schemas, content keys, atomic publish, provenance, manifests."""
