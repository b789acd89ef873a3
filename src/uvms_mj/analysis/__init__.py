"""What reads logs and models: metrics, plots, video, sweeps, sim2real."""
