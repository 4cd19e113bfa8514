"""Sphere-box rows in slots whose link, sphere and box are parameters
(:func:`posturegen.collision.slots.env_parameters`), one row per slot, in the world frame; one
function computes a slot, mapped over the capacity's slots (every slot's link data gathered
at once, every result scattered at once).

Slot s holds sphere c = p_L + R_L s_i of the link L its parameters name, and a box; its row is
softmin_β(v, margin + ENV_SATURATION) - margin with v the smooth sphere-box distance
(:func:`posturegen.collision.soft_min.box_element`): d >= margin where the row is >= 0,
constant once the sphere is ENV_SATURATION beyond the margin. With W the weight of v in the
smooth minimum, g = ∂v/∂c and K = ∇²_c v - βggᵀ:

- ∇row = W·J_Lᵀ A_iᵀ g (A_i = [I, -[ρ_i]×], ρ_i = R_L s_i; z = (p_base, w, qj));
- ∇²(λ·row) = J_Lᵀ A_iᵀ (μK + βλW²ggᵀ) A_i J_L + the kinematics' second derivatives weighted
  by F_L = μg, G_L = μ g s_iᵀ, with μ = λW. A free slot (no link) is the constant 0 (its row
  unbounded); a slot's curvature runs only when μ ≠ 0 (a sphere far from its box: W = 0).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import casadi as ca

from .._cache import memoize
from ..model.kinematics import skew
from ..terms.nlp import BlockDerivatives, BuildContext
from .self_blocks import link_tables
from .slots import BASE_COLUMNS, RowTable, env_index_rows
from .soft_min import (
    ENV_SATURATION,
    SOFT_MIN_BETA,
    box_element,
    compressed,
    gated,
    kinematic_hessian,
    map_columns,
    scatter_sum,
    switched,
)


def _slot(p: Any, R: Any, column: Any, margin: Any) -> dict[str, Any]:
    """A slot's row and its pieces at link pose (p, R): ``column`` (20,) its parameters."""
    s_local, radius, box = column[1:4], column[4], column[5:20]
    rho = R @ s_local
    element = box_element(p + rho, box, radius)
    U = ca.vertcat(element.value, margin + ENV_SATURATION)
    m = ca.mmin(U)
    ex = ca.exp(-SOFT_MIN_BETA * (U - m))
    total = ca.sum1(ex)
    return {
        "row": m - ca.log(total) / SOFT_MIN_BETA - margin,
        "W": ex[0] / total,
        "rho": rho,
        "local": s_local,
        "element": element,
    }


@memoize("env slot kernels", 8)
def _kernels(width: int, nz: int = 0, n_links: int = 0) -> dict[str, ca.Function]:
    """A slot's SX work at its link's pose p (3,), R (9,) (column-major), its parameters
    ``column`` (20,) and the margin, each behind a switch (its index first: whether the slot
    names a link, for ``second`` whether its λ ≠ 0; zeros at index 0 otherwise): ``value`` ->
    row; ``first`` (then the link's compressed twist Jacobian (6·width,)) -> ∇row on its
    link's columns in z (width,) (the same for every capacity); ``second`` (λ, then the
    arguments, the Jacobian, the link and its columns) ->
    (∇²(λ·row) on them without the kinematics' second derivatives (width², column-major),
    their indices in the (nz, nz) Hessian, [μg, vec(μ g sᵢᵀ)] (12,), their indices in
    [F (3N,), G (9N,)])."""
    p, R = ca.SX.sym("p", 3), ca.SX.sym("R", 9)
    column, margin = ca.SX.sym("column", 20), ca.SX.sym("margin")
    J, lam = ca.SX.sym("J", 6 * width), ca.SX.sym("lam")
    link, cols = ca.SX.sym("link"), ca.SX.sym("cols", width)
    s = _slot(p, ca.reshape(R, 3, 3), column, margin)
    e, W, rho = s["element"], s["W"], s["rho"]
    gW = W * e.grad
    mu = lam * W
    Jm = ca.reshape(J, 6, width)
    args = [p, R, column, margin]
    value = ca.Function("env_slot_value", args, [s["row"]])
    g = Jm.T @ ca.vertcat(gW, ca.cross(rho, gW))
    first = ca.Function("env_slot_first", [*args, J], [g])
    H = _curvature_function(width)(mu, SOFT_MIN_BETA * lam * W * W, e.grad, e.curvature, rho, Jm)
    weights = ca.vertcat(mu * e.grad, ca.vec(mu * e.grad @ s["local"].T))
    at_h = ca.vertcat(*[cols + nz * cols[j] for j in range(width)])
    at_w = ca.vertcat(3 * link + ca.DM(range(3)), 3 * n_links + 9 * link + ca.DM(range(9)))
    second = ca.Function(
        "env_slot_second", [lam, *args, J, link, cols], [ca.vec(H), at_h, weights, at_w]
    )
    return {"value": value, "first": first, "second": second}


def kernels(n_links: int, n_joints: int, table_width: int) -> list[ca.Function]:
    """The SX kernels that the env rows of a table of ``n_links`` links and chains of
    ``table_width`` joints run, on a robot of ``n_joints`` joints (every capacity: the same)."""
    width = BASE_COLUMNS + table_width
    own = _kernels(width, BASE_COLUMNS + n_joints, n_links)
    return [_kernels(width)["value"], own["first"], own["second"]]


@memoize("env slot curvatures", 8)
def _curvature_function(width: int) -> ca.Function:
    """(μ, βλW², g (3,), K (3, 3), ρ (3,), J (6, width)) -> JᵀAᵀ(μK + βλW² ggᵀ)AJ, only when
    μ ≠ 0."""
    mu, rank = ca.SX.sym("mu"), ca.SX.sym("rank")
    g, K, rho = ca.SX.sym("g", 3), ca.SX.sym("K", 3, 3), ca.SX.sym("rho", 3)
    J = ca.SX.sym("J", 6, width)
    AJ = ca.horzcat(ca.SX.eye(3), -skew(rho)) @ J  # (3, width)
    H = AJ.T @ ((mu * K + rank * (g @ g.T)) @ AJ)
    return gated(ca.Function(f"env_curvature{width}", [mu, rank, g, K, rho, J], [H]))


class _Args:
    """The MX symbols of the env rows' functions: the slots' parameters (20, E), their indices
    (K, E) (:func:`~.slots.env_indices`), the margin and the link tables: poses (12N,) and,
    for the derivatives, compressed twist Jacobians on z = (p_base, w, qj) (6·D·N,)."""

    def __init__(self, n_links: int, slots: int, width: int) -> None:
        self.C, self.margin = ca.MX.sym("slots", 20, slots), ca.MX.sym("margin")
        self.at = env_index_rows(width)
        self.index = ca.MX.sym("index", self.at["chain"].stop, slots)
        self.poses = ca.MX.sym("poses", 12 * n_links)
        self.J_all = ca.MX.sym("J_all", 6 * width * n_links)
        self.slots = slots

    def gathered(self, table: Any, name: str) -> Any:
        """(size, E) each slot's entries of ``table`` at its indices ``name``."""
        rows = self.index[self.at[name], :]
        return ca.reshape(table.get_nz(False, ca.vec(rows)), rows.shape[0], self.slots)

    def own(self) -> list[Any]:
        """Whether each slot names a link (1, E), and every slot's p (3, E), R (9, E),
        column (20, E) and the margin (1, E)."""
        pose = self.gathered(self.poses, "pose")
        margin = ca.repmat(self.margin, 1, self.slots)
        return [self.C[0, :] >= 0, pose[0:3, :], pose[3:12, :], self.C, margin]


@memoize("env slot values", 8)
def rows_value(n_links: int, slots: int, width: int, compiled: bool) -> ca.Function:
    """(slots (20, E), indices (K, E), margin, poses (12N,)) -> rows (E,); a slot runs only
    when it names a link (else its row is the constant 0, unbounded); ``compiled``: its
    kernels in machine code (:mod:`posturegen.collision.native`)."""
    x = _Args(n_links, slots, width)
    rows = map_columns(switched(_kernels(width)["value"], compiled), slots)(*x.own())
    return ca.Function(
        "env_rows", [x.C, x.index, x.margin, x.poses], [rows.T], {"never_inline": True}
    )


@memoize("env slot derivatives", 8)
def rows_derivatives(
    n_links: int, nz: int, slots: int, width: int, compiled: bool
) -> dict[str, ca.Function]:
    """The rows' derivatives, functions of :func:`rows_value`'s arguments and the compressed
    Jacobians (6·D·N,): ``first`` -> Jacobian (E, nz); ``second`` (λ (E,) last) -> (∇²λᵀrows
    without the kinematics' second derivatives (nz, nz), F (3N,), G (9N,))."""
    work = {k: switched(f, compiled) for k, f in _kernels(width, nz, n_links).items()}
    x = _Args(n_links, slots, width)
    lam = ca.MX.sym("lam", slots)
    names, *own = x.own()
    J = x.gathered(x.J_all, "jacobian")
    cols = x.index[x.at["chain"], :]
    g = map_columns(work["first"], slots)(names, *own, J)  # (D, E)
    at = ca.repmat(ca.DM(range(slots)).T, width, 1) + slots * cols  # (D, E) in the (E, nz)
    jac = ca.reshape(scatter_sum(slots * nz, g, at), slots, nz)
    link = ca.fmax(x.C[0, :], 0)
    lam_s = lam.T * names
    h, at_h, fg, at_fg = map_columns(work["second"], slots)(lam_s != 0, lam_s, *own, J, link, cols)
    H = ca.reshape(scatter_sum(nz * nz, h, at_h), nz, nz)
    FG = scatter_sum(12 * n_links, fg, at_fg)
    opts = {"never_inline": True}
    args = [x.C, x.index, x.margin, x.poses, x.J_all]
    return {
        "first": ca.Function("env_rows_first", args, [jac], opts),
        "second": ca.Function(
            "env_rows_second", [*args, lam], [H, FG[: 3 * n_links], FG[3 * n_links :]], opts
        ),
    }


def env_rows(
    ctx: BuildContext,
    state: Any,
    table: RowTable,
    slots: Any,
    index: Any,
    margin: Any,
    compiled: bool = False,
) -> tuple[Any, Callable[[], BlockDerivatives]]:
    """The env rows of ``slots`` (20, E) with their ``index`` (K, E) in ``state`` (world:
    z = (p_base, w, qj)), links picked among ``table.links``; and the function that builds
    their derivatives; ``compiled``: their kernels in machine code
    (:mod:`posturegen.collision.native`)."""
    links = [int(j) for j in table.links]
    n, width = slots.shape[1], BASE_COLUMNS + table.width
    poses = link_tables(state, links)
    values = rows_value(len(links), n, width, compiled)(slots, index, margin, poses)

    def build() -> BlockDerivatives:
        z = ca.vertcat(ctx.base_position, ctx.base_rotation, ctx.joints)
        J = ctx.kin.twist_jacobians(state, links, ctx.base_rotation)
        columns = [
            [*range(BASE_COLUMNS), *(BASE_COLUMNS + c for c in chain)] for chain in table.chains
        ]
        fns = rows_derivatives(len(links), z.shape[0], n, width, compiled)
        J_all = compressed([J[L] for L in links], columns, width)
        jac = fns["first"](slots, index, margin, poses, J_all)
        lam = ca.SX.sym("lam", n)
        H, F, G = fns["second"](slots, index, margin, poses, J_all, lam)
        weights = {
            L: (F[3 * k : 3 * k + 3], ca.reshape(G[9 * k : 9 * k + 9], 3, 3))
            for k, L in enumerate(links)
        }
        Hk = kinematic_hessian(weights, state, J, z)
        return BlockDerivatives(z=z, jacobian=jac, lam=lam, hessian=H + Hk)

    return values, build
