"""Weighted-A* search over stances (after Escande, Kheddar and Miossec, RAS 2013, the paper's
ref. [8]): the open list holds transitions not yet tried, ordered by their child's estimated
f; each round pops as many as there are workers, solves their postures together
(posturegen.planner.solver), and pushes the successors of the stances that held. A stance is
closed once held at a place (its contacts' surfaces and their positions to 10 cm: a foot
placed further on the same ground is another place); a transition that failed is never tried again,
and its problem is kept (``Stats.failed_problems``) for ``posturegen solve`` to diagnose."""

from __future__ import annotations

import heapq
import itertools
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from ..batch import BatchError
from ..errors import PosturegenError
from ..io.problem_file import problem_from_dict
from ..model.robot import Robot
from ..solver.solve import Result
from .heuristic import STEP_COST, Heuristic
from .layout import pick_target
from .node import Action, Node, Place, Stage, cell, place_of
from .rules import Rules, patch_positions
from .solver import RoundSolver
from .transitions import (
    hold_stage,
    lift_stage,
    soft_unload_stage,
    touch_stage,
    unload_stage,
)

MAX_HOLDS = 1  # postures kept per place (stance and the cells of its contacts)


@dataclass(frozen=True)
class Budget:
    """The search stops after ``nodes`` transitions tried or ``seconds`` [s] of wall time;
    ``posture_iterations``: each posture's IPOPT iterations, all its runs (the stages'
    options.solver.max_call_iter; None: unbounded), so that a stance that cannot be held
    fails fast."""

    nodes: int = 60
    seconds: float = 1800.0
    posture_iterations: int | None = None


@dataclass
class Stats:
    """What the search did: transitions tried, stances held (nodes), postures solved."""

    tried: int = 0
    held: int = 0
    expanded: int = 0
    postures: int = 0
    time_s: float = 0.0
    reached: bool = False
    stop: str = ""
    failures: list[dict[str, str]] = field(default_factory=list)
    failed_problems: list[tuple[str, dict[str, Any]]] = field(default_factory=list)
    hold_fallbacks: int = 0  # adds whose hold failed: the touch posture held the stance
    unloads: int = 0  # removals solved with the patch exactly where it was (fixed, unloaded)
    unload_fallbacks: int = 0  # those that failed, then solved with the soft unload


Progress = Callable[[Stats, Node | None, str], None]


def frame_position(frame: str | None, q: np.ndarray, robot: Robot) -> np.ndarray | None:
    """A frame's position (3,) [m] at posture ``q`` (None for no frame)."""
    if frame is None:
        return None
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return np.array(data.oMf[robot.model.getFrameId(frame)].translation)


class Search:
    """One plan's search; ``run(start)`` gives the goal node (or the best one) and the stats."""

    def __init__(
        self,
        seq: Mapping[str, Any],
        heuristic: Heuristic,
        rules: Rules,
        solver: RoundSolver,
        budget: Budget,
        progress: Progress | None = None,
    ) -> None:
        self.seq, self.heur, self.rules, self.solver = seq, heuristic, rules, solver
        self.budget, self.progress = budget, progress
        self.stats = Stats()
        self.holds: dict[Place, int] = {}
        self.failed: set[tuple[Place, Action]] = set()
        self._open: list[tuple[float, int, Node, Action, Place]] = []
        self._count = itertools.count()

    def run(self, start: Node) -> tuple[Node, Stats]:
        """Search from the start stance until the goal, the budget, or an empty open list."""
        t0 = time.perf_counter()
        self.holds[start.place] = 1
        best = start
        self._push_successors(start)
        while True:
            self.stats.time_s = time.perf_counter() - t0
            if self.heur.reached(best.key, best.extra.get("frame")):
                self.stats.reached, self.stats.stop = True, "goal reached"
                break
            stop = self._stop_reason()
            if stop:
                self.stats.stop = stop
                break
            round_ = self._pop_round()
            for node in self._evaluate(round_):
                if self.heur.reached(node.key, node.extra.get("frame")) or node.h < best.h:
                    best = node
                self._push_successors(node)
        self.stats.time_s = time.perf_counter() - t0
        self.stats.postures = self.solver.solved
        return best, self.stats

    def _closed(self, key: Place) -> bool:
        return self.holds.get(key, 0) >= MAX_HOLDS

    def _stop_reason(self) -> str:
        if not self._open:
            return "no transition left to try"
        if self.stats.tried >= self.budget.nodes:
            return f"node budget ({self.budget.nodes}) spent"
        if self.stats.time_s >= self.budget.seconds:
            return f"time budget ({self.budget.seconds:.0f} s) spent"
        return ""

    def _pop_round(self) -> list[tuple[Node, Action]]:
        """Up to ``workers`` untried transitions to distinct new stances, best first."""
        out: list[tuple[Node, Action]] = []
        keys: set[Place] = set()
        room = min(self.solver.workers, self.budget.nodes - self.stats.tried)
        while self._open and len(out) < room:
            _, _, node, action, child = heapq.heappop(self._open)
            if self._closed(child) or child in keys or (node.place, action) in self.failed:
                continue
            keys.add(child)
            out.append((node, action))
        return out

    def _push_successors(self, node: Node) -> None:
        """Every allowed transition from the node, with its child's estimated f."""
        self.stats.expanded += 1
        for action in self._actions(node):
            child = action.child_place(node.place)
            if self._closed(child):
                continue
            positions = dict(node.positions)
            if action.target is not None:
                positions[action.patch] = np.array(action.target)
            key = action.child_key(node.key)
            h = self.heur.h(key, positions, node.extra.get("frame"))
            f = self.heur.f(node.g + STEP_COST, h, key)
            heapq.heappush(self._open, (f, next(self._count), node, action, child))

    def _actions(self, node: Node) -> list[Action]:
        """Remove any contact (keeping min_contacts), or add a free patch on an allowed
        surface at the point nearest its goal spot within its reach of the soles in contact."""
        on = dict(node.key)
        out: list[Action] = []
        if len(on) > self.rules.min_contacts:
            out += [
                Action("remove", p, s) for p, s in sorted(on.items()) if not self._undo(node, p, s)
            ]
        if len(on) >= self.rules.max_contacts:
            return out
        soles = [node.positions[p] for p in on if "sole" in p] or [node.positions[p] for p in on]
        for p in self.rules.movable():
            if p in on:
                continue
            rule = self.rules.patches[p]
            for s, region in self.heur.areas.items():
                if not rule.allows(s):
                    continue
                target = pick_target(region, self.heur.spots[p], soles, rule.reach)
                if target is not None and not self._undo(node, p, s, target):
                    out.append(Action("add", p, s, tuple(float(v) for v in target)))
        return out

    @staticmethod
    def _undo(node: Node, patch: str, surface: str, target: np.ndarray | None = None) -> bool:
        """The transition would undo the one that led to the node: remove what it added, or
        put back what it removed in the same cell."""
        a = node.action
        if a is None or (a.patch, a.surface) != (patch, surface):
            return False
        return a.kind == "add" or target is None or cell(target) == cell(node.positions[patch])

    def _evaluate(self, round_: list[tuple[Node, Action]]) -> list[Node]:
        """Solve the round's transitions (touch or unload, then the holds): the new nodes."""
        if not round_:
            return []
        self.stats.tried += len(round_)
        first = [self._build(n, a, None) for n, a in round_]
        answers = self._solve(first)
        self._soft_unloads(round_, first, answers)
        holds: list[tuple[int, tuple[str, dict[str, Any], Any] | None]] = []
        for i, ((node, action), built, answer) in enumerate(
            zip(round_, first, answers, strict=True)
        ):
            if action.kind == "add" and isinstance(answer, Result) and answer.success and built:
                holds.append((i, self._build(node, action, (built[2], answer))))
        hold_answers = self._solve([b for _, b in holds])
        hold_of = {i: (b, a) for (i, b), a in zip(holds, hold_answers, strict=True)}
        nodes = []
        for i, (node, action) in enumerate(round_):
            stages = [(first[i], answers[i])]
            if i in hold_of:
                stages.append(hold_of[i])
            child = self._child(node, action, stages)
            if child is not None:
                nodes.append(child)
        return nodes

    def _soft_unloads(
        self, round_: list[tuple[Node, Action]], first: list[Any], answers: list[Any]
    ) -> None:
        """Exact unloads that failed, solved again as soft ones (in place)."""
        if self.rules.release != "unload":
            return
        removes = [i for i, (_, a) in enumerate(round_) if a.kind == "remove" and first[i]]
        self.stats.unloads += len(removes)
        failed = [i for i in removes if not getattr(answers[i], "success", False)]
        if not failed:
            return
        soft = [self._build(*round_[i], None, soft_unload_stage) for i in failed]
        for i, b, a in zip(failed, soft, self._solve(soft), strict=True):
            if b is not None:
                first[i], answers[i] = b, a
                self.stats.unload_fallbacks += 1

    def _build(
        self,
        node: Node,
        action: Action,
        touch: tuple[Any, Result] | None,
        release: Callable[..., dict[str, Any]] | None = None,
    ) -> tuple[str, dict[str, Any], Any] | None:
        """(stage name, problem dict, Problem) of a transition's next posture, None when it
        cannot be built (said in the failures)."""
        try:
            if action.kind == "remove":
                if release is None:
                    release = lift_stage if self.rules.release == "lift" else unload_stage
                data = release(self.seq, node, action, self.heur.goal)
            elif touch is None:
                data = touch_stage(self.seq, node, action, self.rules, self.heur.goal)
            else:
                data = hold_stage(self.seq, node, action, touch, self.rules, self.heur.goal)
            return str(data["name"]), data, problem_from_dict(data)
        except PosturegenError as exc:
            self._fail(node, action, f"cannot build the problem: {exc}")
            return None

    def _solve(self, built: list[tuple[str, dict[str, Any], Any] | None]) -> list[Any]:
        """Answers aligned with ``built`` (None where nothing was built)."""
        ok = [b for b in built if b is not None]
        answers = iter(self.solver.solve([b[1] for b in ok], [b[2] for b in ok]) if ok else [])
        self.stats.postures = self.solver.solved
        return [next(answers) if b is not None else None for b in built]

    def _child(self, node: Node, action: Action, stages: list[tuple[Any, Any]]) -> Node | None:
        """The node of a transition whose postures were all verified, else None (cached as
        failed, with the diagnosis of the posture that failed)."""
        done = []
        for k, (built, answer) in enumerate(stages):
            if built is not None and isinstance(answer, Result) and answer.success:
                done.append(Stage(built[0], built[1], built[2], answer))
                continue
            if built is not None:
                self.stats.failed_problems.append((built[0], built[1]))
                why = f"{built[0]}: {_why(answer)}"
            else:
                why = f"{action.label()}: its problem could not be built"
            if k == 0:
                if built is not None:  # else _build said why
                    self._fail(node, action, why)
                return None
            # the hold failed (IPOPT can stall where the touch left links close): the touch
            # posture, verified, stands for the stance, its new contact unloaded
            self.stats.hold_fallbacks += 1
            if self.progress:
                self.progress(self.stats, None, f"hold not verified, touch kept: {why}")
        if not done:
            return None
        key = action.child_key(node.key)
        robot = done[-1].problem.robot
        positions = patch_positions(robot, done[-1].result.q)
        place = place_of(key, positions)
        if self._closed(place):
            return None
        self.holds[place] = self.holds.get(place, 0) + 1
        contacts = dict(node.contacts)
        if action.kind == "add":
            contacts[action.patch] = action.patch
        else:
            contacts.pop(action.patch)
        frame = frame_position(self.heur.goal.frame, done[-1].result.q, robot)
        g = node.g + STEP_COST
        child = Node(
            key,
            contacts,
            tuple(done),
            positions,
            g,
            self.heur.h(key, positions, frame),
            node,
            action,
            node.depth + 1,
            {"frame": frame},
        )
        self.stats.held += 1
        if self.progress:
            self.progress(self.stats, child, "held " + action.label())
        return child

    def _fail(self, node: Node, action: Action, why: str) -> None:
        self.failed.add((node.place, action))
        self.stats.failures.append(
            {"stance": node.describe(), "action": action.label(), "why": why}
        )
        if self.progress:
            self.progress(self.stats, None, f"failed {action.label()}: {why}")


def _why(answer: Any) -> str:
    if answer is None:
        return "not solved"
    if isinstance(answer, BatchError):
        return answer.message
    return answer.diagnosis or answer.message
