"""Data every stage shares: the scene description, two-agent trajectories, training windows."""
