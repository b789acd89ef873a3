"""The simulated robot: one MuJoCo model in water, its thrusters, its state."""
