"""``sim2radar worlds ...`` commands (procedural indoor worlds)."""
