"""drivers: transports (a port is a URL), framers and device codecs."""
