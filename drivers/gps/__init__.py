"""drivers.gps."""
