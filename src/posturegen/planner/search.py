"""Focal search over stances (after Escande, Kheddar and Miossec, RAS 2013, the paper's
ref. [8]; the order in posturegen.planner.heuristic): the open list holds transitions not yet
tried, with their cost and their child's estimates. With one worker, each round pops the
focal list's first, solves its postures here (posturegen.planner.solver) and pushes the
successors of the stance if it held; with more, each worker has a transition in flight on the
pool, and each answer is taken as it lands (the next focal transition sent at once). A stance
is closed once held at a place (its contacts' surfaces and their positions to 10 cm: a foot
placed further on the same ground is another place); no patch is placed back within REVISIT
of a place it left on the same surface; a transition that failed is never tried again, and
its problem is kept (``Stats.failed_problems``) for ``posturegen solve`` to diagnose."""

from __future__ import annotations

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
from .blocked import blocked_lines
from .heuristic import FOCAL, RECENT, Heuristic
from .layout import anchor_points, pick_target
from .node import Action, Key, Node, Place, Stage, cell, place_of
from .rules import Rules, patch_positions
from .solver import RoundSolver
from .transitions import (
    hold_stage,
    lift_stage,
    touch_stage,
    unload_stage,
)

MAX_HOLDS = 1  # postures kept per place (stance and the cells of its contacts)
REVISIT = 0.1  # [m] a patch is not placed again this near a place it left on the same surface


@dataclass
class _Entry:
    """An untried transition in the open list: its child's ``g + bound`` (the focal
    bound's), its focal order, its depth, its cost [m]."""

    bounded: float
    order: float
    depth: int
    count: int
    node: Node
    action: Action
    child: Place
    cost: float


@dataclass
class _Flight:
    """A transition on the pool: its posture in flight (``built``: stage name, problem dict,
    Problem) and the stages already solved, with their answers."""

    node: Node
    action: Action
    child: Place
    cost: float
    built: tuple[str, dict[str, Any], Any]
    stages: list[tuple[Any, Any]] = field(default_factory=list)


@dataclass(frozen=True)
class Budget:
    """The search stops after ``nodes`` transitions tried or ``seconds`` [s] of wall time;
    ``posture_iterations``: each posture's IPOPT iterations, all its runs (the stages'
    options.solver.max_call_iter; None: unbounded), so that a stance that cannot be held
    fails fast (an unload has at most EXACT_UNLOAD_ITER). Its default: on the four shipped
    plans (2026-12-04) the verified holds took at most 112 iterations, the touches 61-1406,
    and on ATLAS' 2-step stairs one touch needed 1687 (given 3000): at 1500 that plan was not
    reached from a fresh process (41 transitions, 98 s), at 2000 it was (13, 21 s), the four
    shipped plans unchanged (the same transitions, postures and stages)."""

    nodes: int = 60
    seconds: float = 1800.0
    posture_iterations: int | None = 2000


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
    unloads: int = 0  # removals tried, each with the patch exactly where it was (fixed, unloaded)
    # when the goal was not reached: the best stance found, and what kept each goal contact
    # it lacks from it (one line each)
    best: str = ""
    blocked: list[str] = field(default_factory=list)


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
        self._open: list[_Entry] = []
        self._t0 = 0.0  # the run's start (perf_counter) [s]
        self._best: Node  # the stance nearest the goal so far (set by run)
        self._count = itertools.count()

    def run(self, start: Node) -> tuple[Node, Stats]:
        """Search from the start stance until the goal, the budget, or an empty open list:
        in rounds with one worker, with transitions in flight on the pool with more."""
        self._t0 = time.perf_counter()
        self.holds[start.place] = 1
        self._best = start
        self._push_successors(start)
        if self.solver.workers > 1:
            self._in_flight()
        else:
            self._in_rounds()
        self.stats.time_s = time.perf_counter() - self._t0
        self.stats.postures = self.solver.solved
        best = self._best
        if not self.stats.reached:
            self.stats.best = best.describe()
            self.stats.blocked = self.blocked(best)
        return best, self.stats

    def _in_rounds(self) -> None:
        """Pop a round (as many transitions as workers), solve it, take its new stances."""
        while not self._done():
            round_, costs = self._pop_round()
            for node in self._evaluate(round_, costs):
                self._take(node)

    def _in_flight(self) -> None:
        """Keep one transition in flight per worker: each answer that lands is taken at once
        (a touch that verified sends its hold), and a free worker takes the focal list's next
        transition; the transitions still in flight when the goal is reached are abandoned."""
        flights: dict[Any, _Flight] = {}
        while True:
            if self._reached():
                self.solver.abort()
                return
            stop = self._stop_reason()
            if not stop:
                self._launch(flights)
            if not flights:
                self.stats.stop = stop or self._stop_reason() or "no transition left to try"
                return
            for handle, answer in self.solver.wait(list(flights)):
                self._landed(flights, flights.pop(handle), answer)
            self.stats.postures = self.solver.solved

    def _launch(self, flights: dict[Any, _Flight]) -> None:
        """Send focal transitions to distinct new stances until every worker has one."""
        taken = {f.child for f in flights.values()}
        while len(flights) < self.solver.workers and self.stats.tried < self.budget.nodes:
            entry = self._pop_focal(taken)
            if entry is None:
                return
            taken.add(entry.child)
            self._count_tried([entry.action])
            built = self._build(entry.node, entry.action, None)
            if built is not None:
                flight = _Flight(entry.node, entry.action, entry.child, entry.cost, built)
                flights[self.solver.submit(built[1])] = flight

    def _landed(self, flights: dict[Any, _Flight], flight: _Flight, answer: Any) -> None:
        """A posture of a transition in flight is solved: send the hold of a verified touch,
        else take the transition's stance (when all verified)."""
        flight.stages.append((flight.built, answer))
        node, action = flight.node, flight.action
        if len(flight.stages) == 1 and _verified_touch(action, flight.built, answer):
            hold = self._build(node, action, (flight.built[2], answer))
            if hold is not None:
                flight.built = hold
                flights[self.solver.submit(hold[1])] = flight
                return
        child = self._child(node, action, flight.stages, flight.cost)
        if child is not None:
            self._take(child)

    def _take(self, node: Node) -> None:
        """A new stance held: the best so far when nearer the goal, its successors pushed."""
        if self.heur.reached(node.key, node.extra.get("frame")) or node.h < self._best.h:
            self._best = node
        self._push_successors(node)

    def _reached(self) -> bool:
        """The best stance holds the goal (the stats say so)."""
        self.stats.time_s = time.perf_counter() - self._t0
        best = self._best
        if self.heur.reached(best.key, best.extra.get("frame")):
            self.stats.reached, self.stats.stop = True, "goal reached"
        return self.stats.reached

    def _done(self) -> bool:
        """The goal is reached, or a budget spent, or nothing is left to try (said in the
        stats)."""
        if self._reached():
            return True
        self.stats.stop = self._stop_reason()
        return bool(self.stats.stop)

    def blocked(self, node: Node) -> list[str]:
        """Why the stance does not hold the goal (posturegen.planner.blocked)."""
        return blocked_lines(node, self.heur, self.rules, self.stats.failures, self.stats.stop)

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

    def _pop_round(self) -> tuple[list[tuple[Node, Action]], list[float]]:
        """Up to ``workers`` untried transitions to distinct new stances, each the focal
        list's first (:mod:`posturegen.planner.heuristic`), and their costs [m]."""
        out: list[tuple[Node, Action]] = []
        costs: list[float] = []
        keys: set[Place] = set()
        room = min(self.solver.workers, self.budget.nodes - self.stats.tried)
        while len(out) < room:
            entry = self._pop_focal(keys)
            if entry is None:
                break
            keys.add(entry.child)
            out.append((entry.node, entry.action))
            costs.append(entry.cost)
        return out, costs

    def _pop_focal(self, taken: set[Place]) -> _Entry | None:
        """The open transition of least focal order among those whose ``g + bound`` is within
        FOCAL × the least (ties: fewer stages, then first pushed); stale ones dropped."""
        self._open = [
            e
            for e in self._open
            if not self._closed(e.child) and (e.node.place, e.action) not in self.failed
        ]
        live = [e for e in self._open if e.child not in taken]
        if not live:
            return None
        least = min(e.bounded for e in live)
        focal = [e for e in live if e.bounded <= FOCAL * least + 1e-12]
        best = min(focal, key=lambda e: (e.order, e.depth, e.count))
        self._open.remove(best)
        return best

    def _push_successors(self, node: Node) -> None:
        """Every allowed transition from the node, with its cost and its child's estimates."""
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
            recent = action.kind == "remove" and _age(node, action.patch) < RECENT
            cost = self.heur.cost(node.h, h, recent)
            g = node.g + cost
            ahead = self._ahead(node, action, key, h) if action.kind == "remove" else h
            entry = _Entry(
                g + self.heur.bound(key),
                self.heur.f(g, ahead, key),
                node.depth + 1,
                next(self._count),
                node,
                action,
                child,
                cost,
            )
            self._open.append(entry)

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
        for p in self.rules.movable():
            if p in on:
                continue
            for s, target in self._placements(node.key, node.positions, p):
                if self._undo(node, p, s, target) or _revisits(node, p, s, target):
                    continue
                out.append(Action("add", p, s, tuple(float(v) for v in target)))
        return out

    def _placements(
        self, key: Key, positions: Mapping[str, np.ndarray], patch: str
    ) -> list[tuple[str, np.ndarray]]:
        """(surface, target (3,) [m]) of each allowed surface with a point within the
        patch's reach of the soles in contact (of any contact without soles), the point
        nearest the patch's goal spot."""
        anchors = anchor_points(key, positions)
        rule = self.rules.patches[patch]
        out = []
        for s, region in self.heur.areas.items():
            if rule.allows(s):
                target = pick_target(region, self.heur.spots[patch], anchors, rule.reach)
                if target is not None:
                    out.append((s, target))
        return out

    def _ahead(self, node: Node, action: Action, key: Key, h: float) -> float:
        """A removal's h for the focal order: the least h of the stance after the patch's
        best next placement (not back where it was), else h (a removal frees a patch to
        move: this ranks the removals by the progress they allow)."""
        positions, frame = node.positions, node.extra.get("frame")
        best = h
        for s, target in self._placements(key, positions, action.patch):
            gap = float(np.linalg.norm(target - positions[action.patch]))
            if s == action.surface and gap < REVISIT or _revisits(node, action.patch, s, target):
                continue
            moved = {**positions, action.patch: target}
            best = min(best, self.heur.h(key | {(action.patch, s)}, moved, frame))
        return best

    @staticmethod
    def _undo(node: Node, patch: str, surface: str, target: np.ndarray | None = None) -> bool:
        """The transition would undo the one that led to the node: remove what it added, or
        put back what it removed in the same cell."""
        a = node.action
        if a is None or (a.patch, a.surface) != (patch, surface):
            return False
        return a.kind == "add" or target is None or cell(target) == cell(node.positions[patch])

    def _evaluate(self, round_: list[tuple[Node, Action]], costs: list[float]) -> list[Node]:
        """Solve the round's transitions (touch or unload, then the holds): the new nodes
        (``costs``: each transition's [m])."""
        if not round_:
            return []
        self._count_tried([a for _, a in round_])
        first = [self._build(n, a, None) for n, a in round_]
        answers = self._solve(first)
        holds: list[tuple[int, tuple[str, dict[str, Any], Any] | None]] = []
        for i, ((node, action), built, answer) in enumerate(
            zip(round_, first, answers, strict=True)
        ):
            if _verified_touch(action, built, answer):
                holds.append((i, self._build(node, action, (built[2], answer))))
        hold_answers = self._solve([b for _, b in holds])
        hold_of = {i: (b, a) for (i, b), a in zip(holds, hold_answers, strict=True)}
        nodes = []
        for i, (node, action) in enumerate(round_):
            stages = [(first[i], answers[i])]
            if i in hold_of:
                stages.append(hold_of[i])
            child = self._child(node, action, stages, costs[i])
            if child is not None:
                nodes.append(child)
        return nodes

    def _count_tried(self, actions: list[Action]) -> None:
        """The transitions tried, and the removals among them unloaded, in the stats."""
        self.stats.tried += len(actions)
        if self.rules.release == "unload":
            self.stats.unloads += sum(a.kind == "remove" for a in actions)

    def _build(
        self, node: Node, action: Action, touch: tuple[Any, Result] | None
    ) -> tuple[str, dict[str, Any], Any] | None:
        """(stage name, problem dict, Problem) of a transition's next posture, None when it
        cannot be built (said in the failures)."""
        try:
            if action.kind == "remove":
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

    def _child(
        self, node: Node, action: Action, stages: list[tuple[Any, Any]], cost: float
    ) -> Node | None:
        """The node of a transition whose postures were all verified, else None (cached as
        failed, with the diagnosis of the posture that failed); ``cost`` [m] of the
        transition."""
        done = self._verified(node, action, stages)
        if not done:
            return None
        key = action.child_key(node.key)
        robot = done[-1].problem.robot
        positions = patch_positions(robot, done[-1].result.q)
        left = action.child_left(node.left, node.positions)
        place = place_of(key, positions, left)
        if self._closed(place):
            return None
        if action.kind == "add" and _revisits(
            node, action.patch, action.surface, positions[action.patch]
        ):
            self._fail(node, action, "the patch came back to a place it left")
            return None
        self.holds[place] = self.holds.get(place, 0) + 1
        contacts = dict(node.contacts)
        if action.kind == "add":
            contacts[action.patch] = action.patch
        else:
            contacts.pop(action.patch)
        frame = frame_position(self.heur.goal.frame, done[-1].result.q, robot)
        g = node.g + cost
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
            left,
        )
        self.stats.held += 1
        if self.progress:
            self.progress(self.stats, child, "held " + action.label())
        return child

    def _verified(self, node: Node, action: Action, stages: list[tuple[Any, Any]]) -> list[Stage]:
        """The verified stages of a transition ([] when its first failed: the transition
        cached as failed with its diagnosis); a failed hold leaves the touch to stand for the
        stance."""
        done: list[Stage] = []
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
                return []
            # the hold failed (IPOPT can stall where the touch left links close): the touch
            # posture, verified, stands for the stance, its new contact unloaded
            self.stats.hold_fallbacks += 1
            if self.progress:
                self.progress(self.stats, None, f"hold not verified, touch kept: {why}")
        return done

    def _fail(self, node: Node, action: Action, why: str) -> None:
        self.failed.add((node.place, action))
        self.stats.failures.append(
            {"stance": node.describe(), "action": action.label(), "why": why}
        )
        if self.progress:
            self.progress(self.stats, None, f"failed {action.label()}: {why}")


def _verified_touch(action: Action, built: Any, answer: Any) -> bool:
    """The first posture of an add (its touch) was built and verified: its hold comes next."""
    return action.kind == "add" and bool(built) and isinstance(answer, Result) and answer.success


def _age(node: Node, patch: str) -> int:
    """Transitions since the patch's contact was placed (a large number: held from the
    start)."""
    age = 0
    n: Node | None = node
    while n is not None and n.action is not None:
        if n.action.patch == patch and n.action.kind == "add":
            return age
        age += 1
        n = n.parent
    return 1 << 30


def _revisits(node: Node, patch: str, surface: str, target: np.ndarray) -> bool:
    """The patch would be placed within REVISIT of where it was on the surface before a
    transition of the path took it off."""
    n: Node | None = node
    while n is not None and n.parent is not None:
        a = n.action
        if a is not None and a.kind == "remove" and (a.patch, a.surface) == (patch, surface):
            left = n.parent.positions[patch]
            if float(np.linalg.norm(np.asarray(target) - left)) < REVISIT:
                return True
        n = n.parent
    return False


def _why(answer: Any) -> str:
    if answer is None:
        return "not solved"
    if isinstance(answer, BatchError):
        return answer.message
    return answer.diagnosis or answer.message
