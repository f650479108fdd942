"""``sim2radar generate``: the factory main job (procedural worlds -> radar frames + door boxes)."""
