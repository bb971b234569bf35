"""firmware_host.devtools."""
