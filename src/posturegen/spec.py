"""The problem file, by its name before the sub-packages (kept for user code; the module is
:mod:`posturegen.io.problem_file`). A re-export only: nothing in the package imports it."""

from .io.problem_file import CONTACT_TYPES, load_problem, problem_from_dict, read_yaml

__all__ = ["CONTACT_TYPES", "load_problem", "problem_from_dict", "read_yaml"]
