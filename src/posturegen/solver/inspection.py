"""What ``posturegen inspect`` prints: every block of the program a solve starts with, the
collision rows included, and how the collision rows come and go with the active set."""

from __future__ import annotations

from typing import Any

from ..collision.active_set import ENV_PER_LINK, SELF_PER_LINK, ActiveSet, box_label
from ..collision.rows import CollisionTerm
from ..collision.slots import SELF_SLOT_BLOCK
from .problem import Program, SolverOptions
from .qp import registry as qp_registry
from .sqp import native


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
        return "\n".join([problem.summary(), solver_line(problem.solver_options)])
    check, term = initial
    with_rows = Program.of(problem, collision_term=term)
    return "\n".join(
        [with_rows.summary(), solver_line(problem.solver_options), *_collision_lines(check, term)]
    )


def solver_line(options: SolverOptions) -> str:
    """Which solver a solve of the problem runs (SolverOptions.method)."""
    method = options.solver_method()
    qp = options.qp or (qp_registry.available() or ["none"])[0]
    loop = "C" if native.available() else "Python"  # posturegen.solver.sqp.native
    sqp = f"posturegen's SQP ({loop} loop, QP: {qp})"
    what = {
        "auto": f"{sqp}, then IPOPT from the same start when it fails",
        "sqp": sqp,
        "ipopt": "IPOPT",
    }[method]
    return f"solver: {method}: {what}"


def _collision_lines(check: ActiveSet, term: CollisionTerm) -> list[str]:
    """What the collision blocks hold and how they change during a solve."""
    opts = check.options
    cm = 100 * opts.margin
    lines = [f"collision avoidance (margin {cm:.3g} cm), rows at the initial posture:"]
    if opts.self_collision:
        held = sum(1 for _, members in term.self_groups() if members)
        lines.append(
            f"  collision.self: {len(term.self_groups())} rows (one per pair of limbs, {held} "
            f"holding pairs) over {len(term.self_pairs)} sphere pairs of {len(check.links)} "
            f"candidate pairs of links, those closer than {100 * opts.activation:.3g} cm beyond "
            f"their clearance (the {SELF_PER_LINK} closest of each pair of links), in "
            f"{term.fill.blocks} of the program's {term.capacity.self_blocks} blocks of "
            f"{SELF_SLOT_BLOCK} slots"
        )
        if term.maps:
            rows = sum(len(m.discs) for m in term.maps)
            lines.append(
                f"  collision.joint_maps: {rows} rows (discs) for {len(term.maps)} pairs of links "
                "whose proxies overlap at the reference posture: their meshes meet on a region "
                "of the plane of the two joints between them, which the rows keep out of"
            )
    else:
        lines.append("  collision.self: none (self_collision: false)")
    if check.boxes:
        boxes = ", ".join(box_label(b) for b in check.boxes)
        lines.append(
            f"  collision.env: {len(term.env_rows())} rows (one per sphere-box slot) holding "
            f"{len(term.env_pairs)} of {check.n_env_candidates} candidate sphere-box pairs, "
            f"those closer than {cm + 100 * opts.environment_activation:.3g} cm (the "
            f"{ENV_PER_LINK} closest of each link and box); boxes: {boxes}"
        )
    else:
        lines.append("  collision.env: none (no obstacle or support surface to avoid)")
    lines.append(
        "  the rows' pairs are parameters of one program (its slots double when an active set "
        "needs more): after each IPOPT run every candidate pair is "
        "checked, those closer than the margin enter and IPOPT runs again (up to "
        f"{opts.max_rounds} rounds); if a mesh check then fails, the margin grows by 1 cm "
        f"(up to {opts.tighten} times)"
    )
    return lines
