"""firmware_host.rover."""
