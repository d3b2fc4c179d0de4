"""Waypoint planning and tracking for the wheeled robots (ruckig + numpy; no mujoco import): takes poses, returns
wheel speeds.

Where this layer sits and what it may import: docs/layout.md."""
