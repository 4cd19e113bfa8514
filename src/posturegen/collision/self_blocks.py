"""Self rows: one per pair of limbs (fixed per robot), each the smooth minimum of blocks of
sphere-pair slots whose links are parameters (:mod:`posturegen.collision.slots`). Each
function of the rows is one call per block of the capacity: the block's link poses,
compressed twist Jacobians and chain columns gathered from the tables of every link that
carries spheres (by the parameter: a gather in the generated C), its work done by an SX core
behind a switch (a free block costs a branch), its results added where its row and its links'
chains are (a scatter): the program's code does not grow with the active set, and barely
with the capacity.

A block of slots e (sphere i on link a, sphere j on link b) has the smooth minimum
u = softmin_β(v) (β = SOFT_MIN_BETA) of its distances v_e = |c_i - c_j| - (r_i + r_j) - m,
m the joint pair's held clearance; row k is softmin_β over its blocks, computed with one
shift for all rows (CLAMP). Derivatives, in the twist coordinates of a block's two links
(A_i = [I, -[ρ_i]×], ρ_i = R_a s_i, w_e = softmax(-βv)_e, n_e = (c_i - c_j)/|c_i - c_j|):

- the wrenches ``wa = Σ w_e A_iᵀ n_e`` and ``wb = -Σ w_e A_jᵀ n_e``: ∇u = J_aᵀ wa + J_bᵀ wb;
- the curvature M = [[Caa, Cab], [Cabᵀ, Cbb]] with ``Cxy = Σ w_e A_xᵀ K_e A_y`` (signed),
  K_e = (I - n nᵀ)/|u| - β n nᵀ, that is ∇²_c v - β∇_c v∇_c vᵀ;
- the first-order weights ``G_a = Σ w_e n_e s_iᵀ`` and ``G_b = -Σ w_e n_e s_jᵀ`` (and F, the
  wrenches' forces) that weigh the kinematics' second derivatives.

With ω_b a block's weight in its row, ∇row_k = Σ_b ω_b ∇u_b and ∇²(Σ λ_k row_k) =
Σ_b μ_b [J_abᵀ M_b J_ab + kinematic terms] + Σ_k βλ_k ∇row_k∇row_kᵀ, μ_b = λ_k ω_b, each
product taken on the links' chains (a link's twist Jacobian is zero outside the joints between
it and the base). A block's derivatives run only when ω_b > WEIGHT_FLOOR, its curvature only
when μ_b ≠ 0 too (an SQP's inactive rows cost nothing).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import casadi as ca

from .._cache import memoize
from ..model.kinematics import skew
from ..terms.nlp import BlockDerivatives, BuildContext
from .slots import DUMMY_GAP, FREE_ROW, SELF_SLOT_BLOCK, RowTable, index_rows
from .soft_min import (
    SOFT_MIN_BETA,
    compressed,
    kinematic_hessian,
    map_columns,
    scatter_sum,
    switched,
)

# [m] the rows' smooth minima share one shift, the smallest distance of all held blocks m; a
# block's u - m is clamped at CLAMP, so that exp(-β(u - m)) never underflows. A row whose
# blocks are all that far above m reads m + CLAMP - log(n)/β, a lower bound of its distance
# and positive (inactive): only rows that far apart from the closest one are read so.
CLAMP = 0.5
# a block whose weight in its row's smooth minimum is below this adds nothing to the row's
# derivatives (its terms are that small relative to the row's own) and is skipped: a block
# 2 cm above its row's smallest distance weighs exp(-β·0.02) = 2e-9, 4 cm 4e-18
WEIGHT_FLOOR = 1e-12


def _slot_geometry(pa: Any, Ra: Any, pb: Any, Rb: Any, P: Any, clearance: Any) -> dict[str, Any]:
    """Per slot (columns): ρ_i, ρ_j (3, n), unit normals n (3, n), lengths (1, n) and the block's
    distances v (1, n), smooth minimum u and weights w (1, n)."""
    n = P.shape[1]
    rho_i, rho_j = Ra @ P[0:3, :], Rb @ P[3:6, :]
    d = ca.repmat(pa - pb, 1, n) + rho_i - rho_j  # (3, n) c_i - c_j
    length = ca.sqrt(ca.sum1(d * d) + 1e-12)  # (1, n)
    normal = d / ca.repmat(length, 3, 1)
    v = length - P[6, :] - clearance
    m = ca.mmin(v)
    ex = ca.exp(-SOFT_MIN_BETA * (v - m))
    total = ca.sum2(ex)
    return {
        "rho_i": rho_i,
        "rho_j": rho_j,
        "normal": normal,
        "length": length,
        "u": m - ca.log(total) / SOFT_MIN_BETA,
        "w": ex / total,
    }


def _cross_columns(A: Any, B: Any) -> Any:
    """Column-wise cross products (3, n)."""
    return ca.vertcat(
        A[1, :] * B[2, :] - A[2, :] * B[1, :],
        A[2, :] * B[0, :] - A[0, :] * B[2, :],
        A[0, :] * B[1, :] - A[1, :] * B[0, :],
    )


def _wrenches(s: dict[str, Any]) -> tuple[Any, Any, Any]:
    """(wa (6,), wb (6,), the weighted normals (3, n))."""
    nw = s["normal"] * ca.repmat(s["w"], 3, 1)
    force = ca.sum2(nw)
    wa = ca.vertcat(force, ca.sum2(_cross_columns(s["rho_i"], nw)))
    wb = ca.vertcat(-force, -ca.sum2(_cross_columns(s["rho_j"], nw)))
    return wa, wb, nw


def _curvature(s: dict[str, Any]) -> Any:
    """M (12, 12) = [[Caa, Cab], [Cabᵀ, Cbb]], Cxy = Σ A_xᵀ (±w_e K_e) A_y."""
    out = [[ca.SX.zeros(3, 3) for _ in range(4)] for _ in range(3)]
    for e in range(s["normal"].shape[1]):
        nrm, length = s["normal"][:, e], s["length"][e]
        nn = nrm @ nrm.T
        X = s["w"][e] * ((ca.SX.eye(3) - nn) / length - SOFT_MIN_BETA * nn)
        si, sj = skew(s["rho_i"][:, e]), skew(s["rho_j"][:, e])
        for acc, left, right, sign in (
            (out[0], si, si, 1),
            (out[1], si, sj, -1),
            (out[2], sj, sj, 1),
        ):
            Y = -sign * X @ right
            for k, value in enumerate((sign * X, Y, left @ (sign * X), left @ Y)):
                acc[k] = acc[k] + value
    Caa, Cab, Cbb = (ca.vertcat(ca.horzcat(b[0], b[1]), ca.horzcat(b[2], b[3])) for b in out)
    return ca.vertcat(ca.horzcat(Caa, Cab), ca.horzcat(Cab.T, Cbb))


def _symbols(n: int, width: int) -> list[Any]:
    """A block's SX arguments: its links' poses pa (3,), Ra (9,) (column-major), pb, Rb, its
    slots P (7, n) and clearance, and (``width`` > 0) its links' compressed twist Jacobians
    (12·width,: J_a (6, D) then J_b, column-major, each on its link's chain)."""
    out = [ca.SX.sym("pa", 3), ca.SX.sym("Ra", 9), ca.SX.sym("pb", 3), ca.SX.sym("Rb", 9)]
    out += [ca.SX.sym("P", 7, n), ca.SX.sym("clearance")]
    return [*out, ca.SX.sym("J", 12 * width)] if width else out


def _geometry(args: list[Any]) -> dict[str, Any]:
    """:func:`_slot_geometry` of a block's SX arguments."""
    pa, Ra, pb, Rb, P, clearance = args[:6]
    return _slot_geometry(pa, ca.reshape(Ra, 3, 3), pb, ca.reshape(Rb, 3, 3), P, clearance)


@memoize("self block values", 2)
def _value_kernel(n: int) -> ca.Function:
    """(whether the block joins links, then :func:`_symbols` without Jacobians) -> u, its
    smooth minimum, run only for a block that joins links (else 0)."""
    plain = _symbols(n, 0)
    return ca.Function("self_block_value", plain, [_geometry(plain)["u"]])


@memoize("self block kernels", 4)
def _kernels(n: int, width: int, nz: int, rows: int, n_links: int) -> dict[str, ca.Function]:
    """A block's derivatives on its links' chains with the indices where they go, each run
    only when its first arguments say so (zeros at index 0 otherwise). Arguments:
    :func:`_symbols`, then its row, its links ia, ib and their chains (2D,: PADDING beyond).

    - ``first`` (its weight ω in its row first: run when ω > WEIGHT_FLOOR) -> ([J_aᵀwa,
      J_bᵀwb] (2D,), their indices in the rows' Jacobian (R, nz));
    - ``second`` (μ = λω, then ω: run when μ ≠ 0 and ω > WEIGHT_FLOOR) -> (the upper
      triangle of μ·J_abᵀ M J_ab: its values on the links' chains (D(D+1) + D²,) and their
      indices in the (nz, nz) Hessian, μ·[Fa, Fb, Ga, Gb] (24,), their indices in
      [F (3N,), G (9N,)])."""
    args = _symbols(n, width)
    row, ia, ib, chain = (
        ca.SX.sym("row"),
        ca.SX.sym("ia"),
        ca.SX.sym("ib"),
        ca.SX.sym("c", 2 * width),
    )
    where = [row, ia, ib, chain]
    s = _geometry(args)
    wa, wb, nw = _wrenches(s)
    J = ca.reshape(args[6], 6, 2 * width)
    Ja, Jb = J[:, :width], J[:, width:]
    mu = ca.SX.sym("mu")
    g = ca.vertcat(Ja.T @ wa, Jb.T @ wb)
    first = ca.Function("self_block_first", [*args, *where], [g, row + rows * chain])
    M = mu * _curvature(s)
    P = args[4]
    ca_, cb = chain[:width], chain[width:]
    Haa, Hbb = Ja.T @ M[0:6, 0:6] @ Ja, Jb.T @ M[6:12, 6:12] @ Jb
    Hab = Ja.T @ M[0:6, 6:12] @ Jb
    blocks, at_h = _upper_scatter(Haa, Hab, Hbb, ca_, cb, nz)
    weights = mu * ca.vertcat(wa[0:3], wb[0:3], ca.vec(nw @ P[0:3, :].T), ca.vec(-nw @ P[3:6, :].T))
    at_w = ca.vertcat(
        3 * ia + ca.DM(range(3)),
        3 * ib + ca.DM(range(3)),
        3 * n_links + 9 * ia + ca.DM(range(9)),
        3 * n_links + 9 * ib + ca.DM(range(9)),
    )
    second = ca.Function("self_block_second", [mu, *args, *where], [blocks, at_h, weights, at_w])
    return {"first": first, "second": second}


def _upper_scatter(Haa: Any, Hab: Any, Hbb: Any, ca_: Any, cb: Any, n: int) -> tuple[Any, Any]:
    """The block's curvature [[Haa, Hab], [Habᵀ, Hbb]] on the chains ``ca_``, ``cb`` (D,,
    sorted, PADDING beyond) as values and flat (column-major) indices of the upper triangle
    of the (n, n) Hessian: Haa's and Hbb's own upper triangles, and each entry of Hab at
    (min, max) of its columns, twice on the diagonal (Hab and Habᵀ both land there). An
    index built from PADDING falls beyond the matrix."""
    D = Haa.shape[0]
    values, index = [], []
    for H, c in ((Haa, ca_), (Hbb, cb)):
        for j in range(D):
            for i in range(j + 1):
                values.append(H[i, j])
                index.append(c[i] + n * c[j])
    for j in range(D):
        for i in range(D):
            lo, hi = ca.fmin(ca_[i], cb[j]), ca.fmax(ca_[i], cb[j])
            values.append((1 + (ca_[i] == cb[j])) * Hab[i, j])
            index.append(lo + n * hi)
    return ca.vertcat(*values), ca.vertcat(*index)


INDEX_NAMES = ("pose", "jacobian", "chain")


class _Args:
    """The MX symbols of the self rows' functions: the parameters (links (2, B), rows (B,),
    slots (7, 16·B), clearances (B,), free rows (R,), then each block's indices, one matrix
    per kind of :func:`~.slots.index_rows`) and the link tables: poses (12N,: each link's
    position and rotation, column-major) and compressed twist Jacobians (6·D·N,)."""

    def __init__(self, n_links: int, blocks: int, rows: int, width: int) -> None:
        self.links, self.rows = ca.MX.sym("links", 2, blocks), ca.MX.sym("rows", blocks)
        self.slots = ca.MX.sym("slots", 7, SELF_SLOT_BLOCK * blocks)
        self.clear, self.free = ca.MX.sym("clear", blocks), ca.MX.sym("free", rows)
        at = index_rows(width)
        self.index = {
            name: ca.MX.sym(f"at_{name}", at[name].stop - at[name].start, blocks)
            for name in INDEX_NAMES
        }
        self.poses = ca.MX.sym("poses", 12 * n_links)
        self.J_all = ca.MX.sym("J_all", 6 * width * n_links)
        self.blocks, self.n_rows, self.width = blocks, rows, width

    def params(self) -> list[Any]:
        own = [self.links, self.rows, self.slots, self.clear, self.free]
        return [*own, *(self.index[name] for name in INDEX_NAMES)]

    def gathered(self, table: Any, name: str) -> Any:
        """(size, B) each block's entries of ``table`` at its indices ``name``."""
        rows = self.index[name]
        return ca.reshape(table.get_nz(False, ca.vec(rows)), rows.shape[0], self.blocks)

    def own(self) -> list[Any]:
        """Every block's pa (3, B), Ra (9, B), pb, Rb, slots and clearance (1, B)."""
        pose = self.gathered(self.poses, "pose")
        return [
            pose[0:3, :],
            pose[3:12, :],
            pose[12:15, :],
            pose[15:24, :],
            self.slots,
            self.clear.T,
        ]

    def smooth_minima(self, compiled: bool) -> tuple[Any, Any, Any]:
        """(rows (R,), each block's weight in its row (1, B), its row (1, B), sanitized):
        row k = softmin_β over its blocks' u_b with one shift m for all rows (the smallest
        u), each u_b - m clamped at CLAMP (see the module doc); a free row FREE_ROW."""
        joins = self.links[0, :] >= 0
        kernel = switched(_value_kernel(SELF_SLOT_BLOCK), compiled)
        u = map_columns(kernel, self.blocks)(joins, *self.own())
        u = u + (1 - joins) * DUMMY_GAP
        m = ca.mmin(u)
        e = ca.exp(-SOFT_MIN_BETA * ca.fmin(u - m, CLAMP))
        row = ca.fmax(self.rows.T, 0)  # a free block's: 0, where it adds 0
        S = self.free + scatter_sum(self.n_rows, joins * e, row)
        rows = self.free * FREE_ROW + (1 - self.free) * (m - ca.log(S) / SOFT_MIN_BETA)
        weight = joins * e / ca.reshape(S.get_nz(False, ca.vec(row)), 1, self.blocks)
        return rows, weight, row


@memoize("self row values", 8)
def rows_value(n_links: int, blocks: int, rows: int, width: int, compiled: bool) -> ca.Function:
    """(links (2, B), rows (B,), slots (7, 16·B), clearances (B,), free rows (R,), each
    kind of indices (INDEX_NAMES), poses (12N,)) -> the rows (R,); ``compiled``: its
    kernels in machine code (:mod:`posturegen.collision.native`)."""
    x = _Args(n_links, blocks, rows, width)
    values, _, _ = x.smooth_minima(compiled)
    return ca.Function("self_rows", [*x.params(), x.poses], [values], {"never_inline": True})


@memoize("self row derivatives", 8)
def rows_derivatives(
    n_links: int, nz: int, blocks: int, rows: int, width: int, compiled: bool
) -> dict[str, ca.Function]:
    """The rows' derivatives, functions of :func:`rows_value`'s arguments and the compressed
    Jacobians (6·D·N,): ``first`` -> Jacobian (R, nz); ``second`` (λ (R,) last) -> (the upper
    triangle of ∇²λᵀrows without the kinematics' second derivatives (nz, nz; its lower
    triangle zero), F (3N,), G (9N,)) (see the module doc)."""
    work = {
        k: switched(f, compiled)
        for k, f in _kernels(SELF_SLOT_BLOCK, width, nz, rows, n_links).items()
    }
    x = _Args(n_links, blocks, rows, width)
    lam = ca.MX.sym("lam", rows)
    _, weight, row = x.smooth_minima(compiled)
    links = ca.fmax(x.links, 0)
    own = [
        *x.own(),
        x.gathered(x.J_all, "jacobian"),
        row,
        links[0, :],
        links[1, :],
        x.index["chain"],
    ]
    counts = weight > WEIGHT_FLOOR  # (1, B) the blocks whose derivatives run
    g, at = map_columns(work["first"], blocks)(counts, *own)  # (2D, B) each
    g = g * ca.repmat(weight, 2 * width, 1)
    jac = ca.reshape(scatter_sum(rows * nz, g, at), rows, nz)
    mu = ca.reshape(lam.get_nz(False, ca.vec(row)), 1, blocks) * weight
    h, at_h, fg, at_fg = map_columns(work["second"], blocks)(counts * (mu != 0), mu, *own)
    H = scatter_sum(nz * nz, h, at_h)
    c = SOFT_MIN_BETA * lam.T
    upper = map_columns(switched(_rank_one(nz), compiled), rows)(
        c != 0, c, jac.T
    )  # (nz(nz+1)/2, R)
    H = H + scatter_sum(nz * nz, upper, ca.repmat(_upper_index(nz), 1, rows))
    H = ca.reshape(H, nz, nz)  # the upper triangle (the lower one is zero)
    FG = scatter_sum(12 * n_links, fg, at_fg)
    opts = {"never_inline": True}
    params = [*x.params(), x.poses, x.J_all]
    return {
        "first": ca.Function("self_rows_first", params, [jac], opts),
        "second": ca.Function(
            "self_rows_second", [*params, lam], [H, FG[: 3 * n_links], FG[3 * n_links :]], opts
        ),
    }


def _upper_index(n: int) -> ca.DM:
    """The flat (column-major) indices of the upper triangle of an (n, n) matrix, column
    after column."""
    return ca.DM([i + n * j for j in range(n) for i in range(j + 1)])


@memoize("self row rank-one terms", 4)
def _rank_one(nz: int) -> ca.Function:
    """(whether c ≠ 0, c, g (nz,)) -> the upper triangle of c·ggᵀ (column after column), run
    only when c ≠ 0 (a row whose multiplier is 0 adds nothing)."""
    c, g = ca.SX.sym("c"), ca.SX.sym("g", nz)
    upper = [c * g[i] * g[j] for j in range(nz) for i in range(j + 1)]
    return ca.Function("self_row_rank_one", [c, g], [ca.vertcat(*upper)])


def kernels(n_links: int, nz: int, rows: int, width: int) -> list[ca.Function]:
    """The SX kernels that the self rows of these shapes run (every capacity: the same)."""
    own = _kernels(SELF_SLOT_BLOCK, width, nz, rows, n_links)
    return [_value_kernel(SELF_SLOT_BLOCK), own["first"], own["second"], _rank_one(nz)]


def link_tables(state: Any, links: list[int]) -> Any:
    """The pose table of ``links`` (12N,): each link's position then rotation (column-major),
    link after link."""
    return ca.vertcat(*[ca.vertcat(state.p[L], ca.vec(state.R[L])) for L in links])


def self_rows(
    ctx: BuildContext, state: Any, table: RowTable, params: list[Any], compiled: bool = False
) -> tuple[Any, Callable[[], BlockDerivatives]]:
    """The self rows of the blocks of ``params`` (links (2, B), rows (B,), slots (7, 16·B),
    clearances (B,), free rows (R,), each kind of indices (INDEX_NAMES)) in ``state`` (fixed
    base: z = qj), links among ``table.links`` (the joints that carry spheres); and the
    function that builds their derivatives; ``compiled``: their kernels in machine code
    (:mod:`posturegen.collision.native`)."""
    links = [int(j) for j in table.links]
    blocks, n_rows = params[1].shape[0], params[4].shape[0]
    poses = link_tables(state, links)
    values = rows_value(len(links), blocks, n_rows, table.width, compiled)(*params, poses)

    def build() -> BlockDerivatives:
        J = ctx.kin.twist_jacobians(state, links, None)
        columns = [list(c) for c in table.chains]
        nz = ctx.joints.shape[0]
        fns = rows_derivatives(len(links), nz, blocks, n_rows, table.width, compiled)
        J_all = compressed([J[L] for L in links], columns, table.width)
        jac = fns["first"](*params, poses, J_all)
        lam = ca.SX.sym("lam", n_rows)
        H, F, G = fns["second"](*params, poses, J_all, lam)
        weights = {
            L: (F[3 * n : 3 * n + 3], ca.reshape(G[9 * n : 9 * n + 9], 3, 3))
            for n, L in enumerate(links)
        }
        Hk = kinematic_hessian(weights, state, J, ctx.joints)
        return BlockDerivatives(z=ctx.joints, jacobian=jac, lam=lam, hessian=H + Hk)

    return values, build
