"""``sim2radar reconstruct`` command (RGB -> material-labelled scene)."""
