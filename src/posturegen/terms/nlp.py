"""The pieces every term of the posture problem shares: the symbolic program being declared
(:class:`NLP`), what terms share while declaring (:class:`BuildContext`), the term interface
(:class:`Term`), hand-built block derivatives (:class:`BlockDerivatives`) and what a term reads
of the instance it is solved for (:class:`Instance`).

A term declares its variables, parameters, constraints and costs once per problem *structure*
(:meth:`Term.key`), and gives the numeric parameter values, initial guess and bounds of one
instance."""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol

import casadi as ca
import numpy as np

from ..errors import SolveError
from ..model.kinematics import CasadiKinematics, KinematicState, so3_exp
from ..model.robot import Robot
from ..model.scene import Scene

ArrayLike = np.ndarray | float


@dataclass(frozen=True)
class BlockDerivatives:
    """Hand-built derivatives of a constraint block g_b that depends on the variables only
    through z (nz,), a vector of them: ``jacobian`` (rows, nz) = ∂g_b/∂z and ``hessian``
    (nz, nz) = ∇²_z(λᵀg_b) as an expression of the symbols ``lam`` (rows,). The program uses
    them in place of CasADi's automatic derivatives of the block (tested equal to them)."""

    z: ca.SX
    jacobian: ca.SX
    lam: ca.SX
    hessian: ca.SX


class NLP:
    """Symbolic pieces of one program: x (variables), p (parameters), g (constraints), cost."""

    def __init__(self) -> None:
        self.x: dict[str, tuple[ca.SX, np.ndarray, np.ndarray]] = {}
        self.p: dict[str, ca.SX] = {}
        self.g: dict[str, tuple[ca.SX, np.ndarray, np.ndarray]] = {}
        # a block's own derivatives, or the function that builds them when they are needed
        self.derivatives: dict[str, BlockDerivatives | Callable[[], BlockDerivatives]] = {}
        self.costs: dict[str, ca.SX] = {}
        self.outputs: dict[str, ca.SX] = {}
        # (kind, name) -> the position of the term that declared the block (see ordered)
        self.rank: dict[tuple[str, str], int] = {}
        self.declaring = 0  # the position of the term declaring now

    def _own(self, kind: str, name: str) -> None:
        self.rank.setdefault((kind, name), self.declaring)

    def variable(self, name: str, n: int, lb: ArrayLike = -np.inf, ub: ArrayLike = np.inf) -> ca.SX:
        """Declare n variables with (constant) bounds."""
        if name in self.x:
            raise SolveError(f"variable block '{name}' declared twice")
        self._own("x", name)
        sym = ca.SX.sym(name, n)
        self.x[name] = (
            sym,
            np.broadcast_to(lb, (n,)).astype(float),
            np.broadcast_to(ub, (n,)).astype(float),
        )
        return sym

    def parameter(self, name: str, n: int) -> ca.SX:
        """Declare n parameters, given numerically at each solve."""
        if name in self.p:
            raise SolveError(f"parameter block '{name}' declared twice")
        self._own("p", name)
        self.p[name] = ca.SX.sym(name, n)
        return self.p[name]

    def constrain(
        self,
        name: str,
        expr: ca.SX,
        lb: ArrayLike,
        ub: ArrayLike,
        derivatives: BlockDerivatives | Callable[[], BlockDerivatives] | None = None,
    ) -> None:
        """lb <= expr <= ub (use lb == ub for equalities); ``derivatives``: the block's own
        Jacobian and Hessian (see :class:`BlockDerivatives`), or a function that builds them
        (called only when a solver is built from the expressions)."""
        if name in self.g:
            raise SolveError(f"constraint block '{name}' declared twice")
        self._own("g", name)
        expr = ca.vec(ca.SX(expr))
        n = expr.shape[0]
        if derivatives is not None:
            if isinstance(derivatives, BlockDerivatives):
                check_derivatives(name, derivatives, n)
            self.derivatives[name] = derivatives
        self.g[name] = (
            expr,
            np.broadcast_to(lb, (n,)).astype(float),
            np.broadcast_to(ub, (n,)).astype(float),
        )

    def minimize(self, name: str, expr: ca.SX) -> None:
        """Add a scalar term to the cost."""
        self._own("costs", name)
        self.costs[name] = self.costs.get(name, 0) + expr

    def output(self, name: str, expr: ca.SX) -> None:
        """An expression evaluated at the solution (torques, world points...)."""
        self._own("outputs", name)
        self.outputs[name] = ca.vec(ca.SX(expr))

    def copy(self) -> NLP:
        """A copy whose blocks can be added to without touching this one (the expressions,
        immutable, are shared)."""
        out = NLP()
        for name in ("x", "p", "g", "derivatives", "costs", "outputs", "rank"):
            setattr(out, name, dict(getattr(self, name)))
        return out

    def ordered(self) -> NLP:
        """A copy whose blocks are in the order of the terms that declared them (then of
        declaration): the program does not depend on which terms were declared first."""
        out = self.copy()
        kinds = {"derivatives": "g"}
        for kind in ("x", "p", "g", "derivatives", "costs", "outputs"):
            blocks = getattr(self, kind)
            rank = {n: self.rank.get((kinds.get(kind, kind), n), 0) for n in blocks}
            setattr(out, kind, {n: blocks[n] for n in sorted(blocks, key=rank.__getitem__)})
        return out


@dataclass
class BuildContext:
    """What terms share while declaring: the robot, its symbolic state, contact forces."""

    robot: Robot
    nlp: NLP
    kin: CasadiKinematics
    state: KinematicState | None = None
    base_position: ca.SX | None = None  # (3,)
    base_rotation: ca.SX | None = None  # (3,) w of R_base = R0·exp([w]×)
    joints: ca.SX | None = None  # (nj,)
    # (joint id, world point (3,), world force on the robot (3,)) of every force-bearing point
    force_points: list[tuple[int, ca.SX, ca.SX]] = field(default_factory=list)
    torques: ca.SX | None = None  # (nj,) actuated joint torques, set by the equilibrium
    # the collision rows' kernels in machine code (a program for the virtual machine:
    # posturegen.collision.native)
    native_kernels: bool = False
    kernels_pending: bool = False  # wanted in machine code, still being compiled
    # the joint placements in the base's frame (fixed base at the origin), made once for a
    # context and its extensions (the list is shared)
    _base_frame: list[KinematicState] = field(default_factory=list)

    def base_frame_state(self) -> KinematicState:
        """The joint placements with the base at the origin: what distances between links
        (which the base pose does not change) are computed in."""
        if not self._base_frame:
            self._base_frame.append(self.kin.forward(ca.SX.zeros(3), ca.SX.eye(3), self.joints))
        return self._base_frame[0]

    def extended(self) -> BuildContext:
        """A copy that declares into a copy of the program (see :meth:`NLP.copy`)."""
        return dataclasses.replace(self, nlp=self.nlp.copy(), force_points=list(self.force_points))


class Term(ABC):
    """Something that adds variables, constraints or costs to the posture problem.

    A term whose structure changes from one solve of a problem to the next (the collision
    rows: their layout grows) is ``late``: it is declared after every other term, on a copy of
    their program, which is built once for all its variants; its blocks then take their place
    in the term order (:meth:`NLP.ordered`)."""

    name: str
    late: ClassVar[bool] = False

    @abstractmethod
    def key(self) -> tuple[Any, ...]:
        """Everything that changes the program's structure (not its parameter values)."""

    def fingerprint(self) -> tuple[Any, ...]:
        """What the declaration reads, as values: :meth:`key` and what it names by reference
        (a contact's patch, the collision rows' pair list); the compiled library's key across
        processes (:mod:`posturegen.solver.fingerprint`)."""
        return self.key()

    @abstractmethod
    def declare(self, ctx: BuildContext) -> None:
        """Add symbolic variables, parameters, constraints and costs to ``ctx.nlp``."""

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        """Numeric values of the parameters this term declared."""
        return {}

    def initial_guess(self, problem: Instance) -> dict[str, np.ndarray]:
        """Initial values of the variables this term declared (zero when absent)."""
        return {}

    def bounds(self, problem: Instance) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        """Per-instance (lb, ub) of constraint blocks, overriding the declared ones."""
        return {}


class Instance(Protocol):
    """What terms read of the instance being solved (a problem with the solve's overrides,
    :class:`posturegen.solver.problem.Program`): the robot, the scene, the contacts, the initial
    posture, the torque-limit scale and the collision options."""

    @property
    def robot(self) -> Robot: ...
    @property
    def scene(self) -> Scene: ...
    @property
    def contacts(self) -> Sequence[Any]: ...
    @property
    def q_init(self) -> np.ndarray: ...
    @property
    def torque_limit_scale(self) -> float: ...
    @property
    def collision_options(self) -> Any: ...


def check_derivatives(name: str, d: BlockDerivatives, rows: int) -> None:
    """A block's hand-built Jacobian has one row per constraint row and one column per z."""
    if d.jacobian.shape != (rows, d.z.shape[0]):
        raise SolveError(f"constraint block '{name}': Jacobian of the wrong shape")


def base_rotation(R0: ca.SX, w: ca.SX) -> ca.SX:
    """Base orientation R = R0 · exp([w]×): a local exponential map around the initial one."""
    return R0 @ so3_exp(w)
