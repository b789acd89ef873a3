"""The sampled closed loop and experiments."""
