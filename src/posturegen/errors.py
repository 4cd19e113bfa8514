"""One exception hierarchy for posturegen.

Every error a user can trigger derives from :class:`PosturegenError`; its ``str`` is a single
line that names the offending field and how to fix it, so the CLI can print it as is.
"""

from __future__ import annotations


class PosturegenError(Exception):
    """Base class of every posturegen error."""


class InputError(PosturegenError, ValueError):
    """Invalid user input: ``field`` names where it is, ``fix`` says what to do."""

    def __init__(self, field: str, problem: str, fix: str = "") -> None:
        self.field = field
        self.problem = problem
        self.fix = fix
        msg = f"{field}: {problem}"
        if fix:
            msg += f" ({fix})"
        super().__init__(msg)


class ModelError(PosturegenError):
    """A robot model (URDF, SRDF, patches) cannot be used."""


class SolveError(PosturegenError):
    """The solver could not be built or run (not: 'no posture found', which is a result)."""


class PosturegenWarning(UserWarning):
    """Base class of posturegen's warnings: the input is valid, the solve goes on."""


class ImplausibleValueWarning(PosturegenWarning):
    """A value that is valid but most likely a mistake (an angle in degrees, a length in mm):
    the message is one line that names the field, like an :class:`InputError`'s."""
