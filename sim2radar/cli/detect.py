"""``sim2radar train`` / ``sim2radar evaluate`` commands (PointPillars detector)."""
