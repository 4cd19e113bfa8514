"""Self rows built from blocks: the SELF_SLOT_BLOCK sphere-pair slots of a joint pair are one
CasADi function, called in the program (a call node, never inlined) once per block.

A block of slots e (sphere i on joint a, sphere j on joint b) reduces its distances
v_e = |c_i - c_j| - (r_i + r_j) - m (m the joint pair's held clearance) to their smooth
minimum u = softmin_β(v) (β = SOFT_MIN_BETA), and a row, one per pair of limbs, is the smooth
minimum of its blocks' u and a constant cap. This is the smooth minimum over all its slots:
exp(-βu) = Σ_e exp(-βv_e), so the row is unchanged. The block also gives, in the twist
coordinates of its two links (A_i = [I, -[ρ_i]×], ρ_i = R_a s_i, w_e = softmax(-βv)_e,
n_e = (c_i - c_j)/|c_i - c_j|):

- the wrenches ``wa = Σ w_e A_iᵀ n_e`` and ``wb = -Σ w_e A_jᵀ n_e`` (∇u = J_aᵀ wa + J_bᵀ wb);
- the curvature ``Σ w_e A_iᵀ K_e A_j`` per pair of its links, K_e = (I - n nᵀ)/|u| - β n nᵀ
  (that is ∇²_c v - β ∇_c v ∇_c vᵀ), with the sign of ∂v/∂c_i · ∂v/∂c_j;
- the first-order weights ``G_a = Σ w_e n_e s_iᵀ`` and ``G_b = -Σ w_e n_e s_jᵀ`` (and F, the
  wrenches' forces) that weigh the kinematics' second derivatives.

The row's Hessian is then Σ_b W_b Σ_e w_e (∇²v_e - β∇v_e∇v_eᵀ) + β∇r∇rᵀ with W = softmax over
the blocks, exactly as for one smooth minimum over every slot. A program holds as many calls
as blocks and the function's code once, so a new layout builds in a fraction of the time
that writing every slot's expressions took, and its generated C is a small file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca

from .._cache import memoize
from ..model.kinematics import skew
from ..terms.nlp import BlockDerivatives, BuildContext
from .soft_min import SOFT_MIN_BETA, kinematic_hessian

# sphere-pair slots per block: a joint pair has a multiple of it
SELF_SLOT_BLOCK = 16


@dataclass(frozen=True)
class Block:
    """One call: row ``row``, joints a < b, the block's slot parameters (7, SELF_SLOT_BLOCK)
    and the pair's clearance."""

    row: int
    a: int
    b: int
    slots: Any
    clearance: Any


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


def _curvatures(s: dict[str, Any]) -> tuple[Any, Any, Any]:
    """(Σ A_iᵀ X A_i, Σ A_iᵀ(-X)A_j, Σ A_jᵀ X A_j) (6, 6) with X = w_e K_e per slot."""
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
    return tuple(ca.vertcat(ca.horzcat(b[0], b[1]), ca.horzcat(b[2], b[3])) for b in out)  # type: ignore[return-value]


@memoize("self block functions", 4)
def block_functions(n: int) -> dict[str, ca.Function]:
    """The block's functions of (pa, Ra, pb, Rb, P (7, n), clearance), link poses in the rows'
    frame: ``value`` -> u; ``first`` -> (u, wa, wb); ``second`` -> (u, wa, wb, Caa, Cab, Cbb,
    Ga, Gb) (see the module doc)."""
    pa, pb = ca.SX.sym("pa", 3), ca.SX.sym("pb", 3)
    Ra, Rb = ca.SX.sym("Ra", 3, 3), ca.SX.sym("Rb", 3, 3)
    P, clearance = ca.SX.sym("P", 7, n), ca.SX.sym("clearance")
    args = [pa, Ra, pb, Rb, P, clearance]
    s = _slot_geometry(*args)
    wa, wb, nw = _wrenches(s)
    Caa, Cab, Cbb = _curvatures(s)
    Ga, Gb = nw @ P[0:3, :].T, -nw @ P[3:6, :].T
    opts = {"never_inline": True}
    return {
        "value": ca.Function(f"self_block{n}", args, [s["u"]], opts),
        "first": ca.Function(f"self_block{n}_first", args, [s["u"], wa, wb], opts),
        "second": ca.Function(
            f"self_block{n}_second", args, [s["u"], wa, wb, Caa, Cab, Cbb, Ga, Gb], opts
        ),
    }


def _arguments(state: Any, block: Block) -> list[Any]:
    """The block's function arguments: its links' poses in ``state``, its slots, clearance."""
    a, b = block.a, block.b
    return [state.p[a], state.R[a], state.p[b], state.R[b], block.slots, block.clearance]


def _row_weights(us: list[Any], cap: Any) -> tuple[Any, Any]:
    """(softmin_β(us, cap), the weights W (len(us),) of the blocks)."""
    U = ca.vertcat(*us, cap)
    m = ca.mmin(U)
    ex = ca.exp(-SOFT_MIN_BETA * (U - m))
    total = ca.sum1(ex)
    return m - ca.log(total) / SOFT_MIN_BETA, ex[: len(us)] / total


def self_block_rows(
    ctx: BuildContext, state: Any, blocks: list[Block], caps: list[Any]
) -> tuple[Any, Callable[[], BlockDerivatives]]:
    """The rows softmin_β(blocks' u, cap_k) (one per cap) in ``state`` (fixed base: z = qj),
    and the function that builds their derivatives (see the module doc)."""
    fns = block_functions(SELF_SLOT_BLOCK)
    calls = [fns["value"](*_arguments(state, b)) for b in blocks]
    values = [
        _row_weights([u for u, b in zip(calls, blocks, strict=True) if b.row == k], cap)[0]
        for k, cap in enumerate(caps)
    ]

    def build() -> BlockDerivatives:
        return _derivatives(ctx, state, blocks, caps, fns)

    return ca.vertcat(*values), build


def _derivatives(
    ctx: BuildContext,
    state: Any,
    blocks: list[Block],
    caps: list[Any],
    fns: dict[str, ca.Function],
) -> BlockDerivatives:
    """The rows' Jacobian (from the ``first`` calls) and the Hessian of λᵀrows (from the
    ``second`` calls), in z = qj."""
    z = ctx.joints
    lam = ca.SX.sym("lam", len(caps))
    links = sorted({b.a for b in blocks} | {b.b for b in blocks})
    J = ctx.kin.twist_jacobians(state, links, None)
    nz = z.shape[0]
    first = [fns["first"](*_arguments(state, b)) for b in blocks]
    second = [fns["second"](*_arguments(state, b)) for b in blocks]
    jac_rows = []
    H = ca.SX(nz, nz)
    curv: dict[tuple[int, int], Any] = {}
    weights: dict[int, tuple[Any, Any]] = {L: (ca.SX.zeros(3), ca.SX.zeros(3, 3)) for L in links}
    for k, cap in enumerate(caps):
        mine = [m for m, b in enumerate(blocks) if b.row == k]
        _, W = _row_weights([first[m][0] for m in mine], cap)
        jac_rows.append(_gradient(J, [blocks[m] for m in mine], [first[m] for m in mine], W, nz).T)
        _, W2 = _row_weights([second[m][0] for m in mine], cap)
        grad = _gradient(J, [blocks[m] for m in mine], [second[m] for m in mine], W2, nz)
        H = H + lam[k] * SOFT_MIN_BETA * (grad @ grad.T)
        for t, m in enumerate(mine):
            b, (_, wa, wb, Caa, Cab, Cbb, Ga, Gb) = blocks[m], second[m]
            c = lam[k] * W2[t]
            for key, C in (((b.a, b.a), Caa), ((b.a, b.b), Cab), ((b.b, b.b), Cbb)):
                curv[key] = curv.get(key, 0) + c * C
            for L, w, G in ((b.a, wa, Ga), (b.b, wb, Gb)):
                F0, G0 = weights[L]
                weights[L] = (F0 + c * w[0:3], G0 + c * G)
    for (La, Lb), M in curv.items():
        part = J[La].T @ M @ J[Lb]
        H = H + (part if La == Lb else part + part.T)
    Hk = kinematic_hessian(weights, state, J, z)
    if Hk is not None:
        H = H + Hk
    jac = ca.vertcat(*jac_rows) if jac_rows else ca.SX(0, nz)
    return BlockDerivatives(z=z, jacobian=jac, lam=lam, hessian=H)


def _gradient(J: dict[int, Any], blocks: list[Block], outs: list[Any], W: Any, nz: int) -> Any:
    """∇_z row (nz,) = Σ_b W_b (J_aᵀ wa_b + J_bᵀ wb_b), the wrenches summed per link first."""
    wrench: dict[int, Any] = {}
    for t, (b, out) in enumerate(zip(blocks, outs, strict=True)):
        wrench[b.a] = wrench.get(b.a, 0) + W[t] * out[1]
        wrench[b.b] = wrench.get(b.b, 0) + W[t] * out[2]
    grad = ca.SX(nz, 1)
    for L, w in wrench.items():
        grad = grad + J[L].T @ w
    return grad
