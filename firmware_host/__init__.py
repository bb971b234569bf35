"""firmware_host: the run loop, the command line and the run modes of fdi-bridge."""

__version__ = "0.1.0"
