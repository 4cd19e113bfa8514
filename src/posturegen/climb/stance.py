"""Stance transitions (paper sec. IV-E): a contact found as non-inclusive becomes a fixed,
force-bearing contact of the next posture, whose forces act at the vertices of the
intersection of the two polygons; another contact may be released at the same time."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..solver.problem import Problem
from ..solver.solve import Result
from ..terms.contacts import Contact, FixedContact
from ..terms.cop import DEFAULT_COP_MARGIN
from ..terms.friction import FrictionModel


def frozen_pose(contact: Contact, model: pin.Model, q: np.ndarray) -> tuple[np.ndarray, float]:
    """Where ``contact`` is at posture q, as the pose (position (2,) [m], yaw [rad]) of the
    fixed contact it becomes for the next stance: a fixed contact keeps its own (realized to
    1e-6), a floating one takes its realized pose. The one place a contact is frozen
    (:func:`next_problem`, the ``keep`` contacts of posturegen.climb.sequence)."""
    return contact.realized_pose(model, q)


def next_problem(
    problem: Problem,
    result: Result,
    fix: str,
    release: str | None = None,
    tasks: list | None = None,
) -> Problem:
    """The problem of the next stance: contact ``fix`` (geometric, support, inclusive or point)
    frozen at its pose in ``result`` as a ``fixed`` contact (a contact already fixed stays as
    it is: ``result`` realized its pose) with the CoP margin of the contact, or else of the
    problem, contact ``release`` removed, the
    posture of ``result`` as the initial posture (warm start), ``tasks`` replacing the tasks
    when given."""
    names = [c.name for c in problem.contacts]
    if fix not in names:
        raise InputError("fix", f"no contact named '{fix}'", f"contacts: {', '.join(names)}")
    if release is not None and release not in names:
        raise InputError(
            "release", f"no contact named '{release}'", f"contacts: {', '.join(names)}"
        )
    if release == fix:
        raise InputError("release", "cannot release the contact being fixed", "name another one")
    if not result.success:
        raise InputError("result", "the posture was not verified", "fix a contact of a success")
    old = problem.contacts[names.index(fix)]
    if old.fixed_in_place:
        fixed = old  # already fixed: it stays where it is (its realized pose, to 1e-6)
    else:
        position, yaw = frozen_pose(old, problem.robot.model, result.q)
        friction = getattr(old, "friction", FrictionModel())
        margin = getattr(old, "cop_margin", problem.cop_margin)
        fixed = FixedContact(
            old.name,
            old.patch,
            old.surface,
            position,
            yaw,
            old.mu,
            friction,
            cop_margin=DEFAULT_COP_MARGIN if margin is None else margin,
        )
    contacts = [fixed if c.name == fix else c for c in problem.contacts if c.name != release]
    return dataclasses.replace(
        problem,
        contacts=contacts,
        q_init=result.q.copy(),
        tasks=list(problem.tasks if tasks is None else tasks),
    )
