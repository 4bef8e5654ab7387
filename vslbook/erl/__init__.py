"""Episode-based RL (Chapters 2–4): search distributions over movement-primitive parameters."""
