"""One exception family for user-facing errors.

Every error a user can cause (bad file, bad shape, unknown name) is raised as a
:class:`ControlMMError` whose message is one line naming the bad value and what is
allowed. The CLI prints that line and exits with code 2; library callers can catch it.
"""

from __future__ import annotations


class ControlMMError(ValueError):
    """A user-facing error with a one-line message (CLI exit code 2)."""

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(str(message).split()))


class InputFileError(ControlMMError):
    """A file is missing, unreadable, or in a format that is not understood."""


class ShapeError(ControlMMError):
    """An array has the wrong shape or holds NaN/inf."""
