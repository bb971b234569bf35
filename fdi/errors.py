"""The one exception tree of fdi-bridge.

Library exceptions (``serial.SerialException``, ``pynmea2.ParseError``, ``OSError`` ...) are
translated where they enter the project, with ``raise ... from err``. Bad *data* (a malformed
sentence, a bad frame) is normally counted and logged rather than raised; these exceptions are for
conditions a caller must act on.
"""

from __future__ import annotations

from collections.abc import Sequence


class FdiBridgeError(Exception):
    """Root of every exception fdi-bridge raises on purpose."""


class ConfigError(FdiBridgeError):
    """A configuration file is missing, unreadable or invalid.

    The message always names the file, the key, what was expected and what was found.
    """

    def __init__(self, file: str, key: str, expected: str, found: str) -> None:
        self.file = file
        self.key = key
        self.expected = expected
        self.found = found
        super().__init__(f"{file}: {key}: expected {expected}, found {found}")


class ConfigErrors(ConfigError):
    """Several errors in one configuration file; ``errors`` lists each, in file order.

    The attributes of :class:`ConfigError` are the first error's; the message has one line per
    error."""

    def __init__(self, errors: Sequence[ConfigError]) -> None:
        first = errors[0]
        super().__init__(first.file, first.key, first.expected, first.found)
        self.errors = list(errors)
        self.args = ("\n".join(str(e) for e in self.errors),)


class PortError(FdiBridgeError):
    """A transport could not be opened, read or written."""


class PortClosedError(PortError):
    """The far end of a transport went away (USB unplugged, pty closed, socket closed)."""


class DecodeError(FdiBridgeError):
    """A frame or sentence could not be decoded. Carries a short machine-readable reason."""

    def __init__(self, reason: str, detail: str = "") -> None:
        self.reason = reason
        self.detail = detail
        super().__init__(f"{reason}: {detail}" if detail else reason)


class CaptureFormatError(FdiBridgeError):
    """A capture file is not in the fdi-bridge capture format (or its header is damaged)."""


class EstimatorError(FdiBridgeError):
    """An estimator was given input it cannot use (for example an IMU rate too low)."""


class UsageError(FdiBridgeError):
    """A command-line argument is wrong (a path, URL or number): the command exits 2 before its
    work starts. The message names the option, what was expected and what was found."""


class EndpointError(UsageError, PortError):
    """A network endpoint cannot be opened at start (its port held by another process, its
    address invalid or not on this machine): the command exits 2 before its work starts, with
    one line naming the URL and, where it can, the process that holds the port."""
