"""firmware_host.insgnss."""
