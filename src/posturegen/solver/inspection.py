"""What ``posturegen inspect`` prints: every block of the program a solve starts with, the
collision rows included, and how the collision rows come and go with the active set."""

from __future__ import annotations

from typing import Any

from ..collision.active_set import SELF_PER_LINK, ActiveSet, box_label
from ..collision.rows import ENV_SLOT_BLOCK, CollisionTerm
from .problem import Program


def initial_collision_term(problem: Any) -> tuple[ActiveSet, CollisionTerm] | None:
    """The candidates of ``problem`` and the collision rows of its first IPOPT run: the
    pairs near at the initial posture (None without collision avoidance). A later problem of
    the same structure in the same process also starts with the pairs its predecessors
    needed (up to 160)."""
    opts = problem.collision_options
    if opts is None:
        return None
    active = ActiveSet.of(problem)
    active.grow(active.scan(problem.q_init, opts.margin))
    return active, active.term(opts.margin)


def describe(problem: Any) -> str:
    """The program's variable and constraint blocks and its costs
    (:meth:`posturegen.solver.problem.Problem.summary`) with the collision rows at the initial
    posture, and the collision avoidance's candidates."""
    initial = initial_collision_term(problem)
    if initial is None:
        return problem.summary()
    check, term = initial
    with_rows = Program.of(problem, collision_term=term)
    return "\n".join([with_rows.summary(), *_collision_lines(check, term)])


def _collision_lines(check: ActiveSet, term: CollisionTerm) -> list[str]:
    """What the collision blocks hold and how they change during a solve."""
    opts = check.options
    cm = 100 * opts.margin
    lines = [f"collision avoidance (margin {cm:.3g} cm), rows at the initial posture:"]
    if opts.self_collision:
        lines.append(
            f"  collision.self: {len(term.self_groups())} rows (one per pair of limbs) over "
            f"{len(term.self_pairs)} sphere pairs of {len(check.links)} candidate pairs of "
            f"links, those closer than {100 * opts.activation:.3g} cm beyond their clearance "
            f"(the {SELF_PER_LINK} closest of each pair of links)"
        )
    else:
        lines.append("  collision.self: none (self_collision: false)")
    if check.boxes:
        boxes = ", ".join(box_label(b) for b in check.boxes)
        lines.append(
            f"  collision.env: {len(term.env_rows())} rows (one per sphere slot and box, "
            f"{ENV_SLOT_BLOCK} slots per link and box) holding {len(term.env_pairs)} of "
            f"{check.n_env_candidates} candidate sphere-box pairs, those closer than "
            f"{cm + 100 * opts.environment_activation:.3g} cm; boxes: {boxes}"
        )
    else:
        lines.append("  collision.env: none (no obstacle or support surface to avoid)")
    lines.append(
        "  rows come and go with the active set: after each IPOPT run every candidate pair is "
        "checked, those closer than the margin enter and IPOPT runs again (up to "
        f"{opts.max_rounds} rounds); if a mesh check then fails, the margin grows by 1 cm "
        f"(up to {opts.tighten} times)"
    )
    return lines
