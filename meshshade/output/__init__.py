"""Outputs: per-pixel rendering of baked radiance, tone mapping, model comparison, profile reports."""
