"""User-facing errors.

A :class:`GnomonError` is a problem with the user's input (a file, a key in a
field log, a frame): the CLI prints its message as one line and exits with
code 2. Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations


class GnomonError(Exception):
    """A problem with the user's input, reported as one line, exit code 2."""


class FieldLogError(GnomonError):
    """A missing, unknown or invalid key in a field log (names file and key)."""


class FrameError(GnomonError):
    """A frame that is missing, unreadable or inconsistent (names the frame)."""


class OutputError(GnomonError):
    """An output that cannot be written: no space, file too large, read-only, permission (names the path)."""
