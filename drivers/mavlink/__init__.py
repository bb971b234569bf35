"""drivers.mavlink."""
