"""Probes: pressure at a point, the water level along a vertical line, the fluid's force on
a wall segment or a body, sampled during the run (docs/design.md §5.1)."""
