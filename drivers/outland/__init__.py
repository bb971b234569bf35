"""drivers.outland."""
