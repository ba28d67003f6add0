"""The web layer: every HTTP route (participant and researcher), their dependencies, headers,
rate limits and lockout, and what `tomstudy serve` checks before workers start."""
