"""User-facing errors.

A :class:`GnomonError` is a problem with the user's input (a file, a key in a
field log, a frame): the CLI prints its message as one line and exits with
code 2. Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

from collections.abc import Iterable


class GnomonError(Exception):
    """A problem with the user's input, reported as one line, exit code 2."""


class FieldLogError(GnomonError):
    """A missing, unknown or invalid key in a field log (names file and key)."""


class FrameError(GnomonError):
    """A frame that is missing, unreadable or inconsistent (names the frame)."""


class CorruptFrameError(FrameError):
    """A frame file whose encoded data is corrupt inside: the decoder warned (and would have handed back
    garbage where the data was lost). ``path``: the file; ``reason``: the decoder's words; ``hint``: what
    the user can do, appended to the message."""

    def __init__(self, path: object, reason: str, hint: str = ""):
        super().__init__(f"{path}: corrupt image data: {reason}" + (f"; {hint}" if hint else ""))
        self.path = path
        self.reason = reason


class OutputError(GnomonError):
    """An output that cannot be written: no space, file too large, read-only, permission (names the path)."""


class KernelError(GnomonError, ValueError):
    """The Rust kernel refused its input (one subclass per ``gnomon-core`` ``KernelError`` variant).

    Also a :class:`ValueError`: the kernel's inputs are values of the wrong kind or range.
    """


class KernelParameterError(KernelError):
    """A kernel parameter outside its documented range (``InvalidParameter``), or an unknown dtype."""


class KernelArrayError(KernelError):
    """An array of the wrong dtype or shape handed to the kernel (``LengthMismatch``)."""


class KernelLutError(KernelError):
    """A decoding table that is not finite and non-decreasing (``InvalidLut``)."""


class KernelFramesError(KernelError, FrameError):
    """No frames before ``finish``, or more frames than one tracker can index (``NoFrames``, ``TooManyFrames``)."""


class FrameNote(str):
    """A warning about particular frames of the capture: the text, and the frames (capture indices) it
    concerns, so that a recording shows it at those frames. Everywhere else it is the plain string."""

    frames: tuple[int, ...]

    def __new__(cls, text: str, frames: Iterable[int] = ()) -> FrameNote:
        note = super().__new__(cls, text)
        note.frames = tuple(int(f) for f in frames)
        return note

    def reworded(self, text: str) -> FrameNote:
        """The same kind of note, about the same frames, with another text (e.g. prefixed)."""
        return type(self)(text, self.frames)


class Remark(FrameNote):
    """A fact about a scan the user may want to know but need not act on (frames levelled under clouds,
    night frames skipped, pixels refused as another shadow's): a scan reports it as a note, apart from
    its warnings, which each say what to do."""
