"""Experiments behind the figures: configuration in, numbers (or a run directory) out."""
