"""firmware_host.runtime."""
