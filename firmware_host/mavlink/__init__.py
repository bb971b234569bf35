"""firmware_host.mavlink."""
