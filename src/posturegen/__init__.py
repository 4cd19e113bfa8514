"""posturegen: statically stable multi-contact postures of humanoid robots, with non-inclusive
contacts (Brossette et al., IROS 2014).

    >>> import posturegen as pg
    >>> problem = pg.load_problem("problem.yaml")
    >>> result = pg.solve(problem)
    >>> result.success, result.q, result.torques
    >>> results = pg.solve_many(["a.yaml", "b.yaml"], workers=2)  # every core, input order
"""

from . import _threads  # noqa: F401  (first: before numpy loads OpenBLAS)
from ._cache import clear_caches
from .batch import BatchError, solve_many
from .errors import (
    ImplausibleValueWarning,
    InputError,
    ModelError,
    PosturegenError,
    PosturegenWarning,
    SolveError,
)
from .io.problem_file import load_problem, problem_from_dict
from .model.robot import Robot, load_robot
from .model.scene import Obstacle, Scene, Surface
from .planner import PlanReport, plan
from .solver.diagnose import diagnose
from .solver.problem import Problem, SolverOptions
from .solver.solve import Result, solve
from .terms import contacts, costs, tasks
from .terms.nlp import Term
from .terms.tasks import Task, register_task
from .verify import VerifyReport, verify_posture

__all__ = [
    "PlanReport",
    "plan",
    "BatchError",
    "ImplausibleValueWarning",
    "InputError",
    "ModelError",
    "Obstacle",
    "PosturegenError",
    "PosturegenWarning",
    "Problem",
    "Result",
    "Robot",
    "Scene",
    "SolveError",
    "SolverOptions",
    "Surface",
    "Task",
    "Term",
    "VerifyReport",
    "clear_caches",
    "contacts",
    "costs",
    "diagnose",
    "load_problem",
    "load_robot",
    "problem_from_dict",
    "register_task",
    "solve",
    "solve_many",
    "tasks",
    "verify_posture",
]
__version__ = "0.1.0"
