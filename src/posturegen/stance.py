"""Stance transitions, by their name before the sub-packages (kept for user code; the module is
:mod:`posturegen.climb.stance`). A re-export only: nothing in the package imports it."""

from .climb.stance import next_problem

__all__ = ["next_problem"]
