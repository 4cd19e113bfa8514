"""posturegen: statically stable multi-contact postures of humanoid robots, with non-inclusive
contacts (Brossette et al., IROS 2014).

    >>> import posturegen as pg
    >>> problem = pg.load_problem("problem.yaml")
    >>> result = pg.solve(problem)
    >>> result.success, result.q, result.torques
    >>> results = pg.solve_many(["a.yaml", "b.yaml"], workers=2)  # every core, input order
"""

from . import _threads  # noqa: F401  (first: before numpy loads OpenBLAS)
from .batch import BatchError, solve_many
from .diagnose import diagnose
from .errors import (
    ImplausibleValueWarning,
    InputError,
    ModelError,
    PosturegenError,
    PosturegenWarning,
    SolveError,
)
from .planner import PlanReport, plan
from .problem import Problem, SolverOptions
from .robot import Robot, load_robot
from .scene import Obstacle, Scene, Surface
from .solve import Result, solve
from .spec import load_problem, problem_from_dict
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
    "VerifyReport",
    "diagnose",
    "load_problem",
    "load_robot",
    "problem_from_dict",
    "solve",
    "solve_many",
    "verify_posture",
]
__version__ = "0.1.0"
