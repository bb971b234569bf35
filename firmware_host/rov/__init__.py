"""firmware_host.rov."""
