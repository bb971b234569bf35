"""firmware_host.commands."""
