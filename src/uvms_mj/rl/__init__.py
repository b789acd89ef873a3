"""Reinforcement-learning environments (dm_control, gymnasium)."""
