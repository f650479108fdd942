"""``sim2radar simulate`` and ``sim2radar demo`` (owned by the radar/storage work)."""
