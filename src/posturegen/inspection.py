"""What ``posturegen inspect`` prints, by its name before the sub-packages (kept for user code;
the module is :mod:`posturegen.solver.inspection`). A re-export only: nothing in the package
imports it."""

from .solver.inspection import describe, initial_collision_term

__all__ = ["describe", "initial_collision_term"]
