"""The sphere-box rows as smooth CasADi expressions and their own exact derivatives: each
row is the smooth minimum (-LSE, SOFT_MIN_BETA) of elements, a distance between a sphere and
a box (:func:`box_element`) and a constant, whose gradients and curvatures in the centres are
known; :func:`soft_min_rows` maps them to the program's variables through the links' twist
Jacobians (see :mod:`posturegen.collision.rows` for the rows themselves, and
:mod:`posturegen.collision.self_blocks` for the self rows, built from blocks of slots)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import casadi as ca
import numpy as np

from ..model.kinematics import skew
from ..terms.nlp import BlockDerivatives, BuildContext
from .boxes import BETA

# [1/m] sharpness of the smooth minimum over a link pair's sphere pairs: conservative by at most
# log(n)/β (n sphere pairs, 1.5 cm for 20), by much less when one pair is the closest by a few
# mm. 200 /m: talos-near-body-collision took 26.5 median iterations, 500 /m 28.5, 1000 /m 32.5.
SOFT_MIN_BETA = 1000.0
# [m] a sphere-box row is saturated at margin + this: -LSE(-d, -(margin + s)) >= margin, which
# still implies d >= margin (a smooth minimum is below each of its arguments) and is constant
# once the sphere is a few cm away. IPOPT writes an inequality row as g(x) - s = 0 with a slack
# s >= 0, so a far row's nonlinearity along a long step counted as infeasibility and cut steps
# that the row had no reason to stop: talos-box-collision took 29.5 median iterations
# unsaturated, 19 at 5 cm (18 at 5 and 10 cm on another seed, 22.5 at 3 cm). Self rows are
# left unsaturated: the far ones' barrier keeps the arm off the body on its way, and saturated
# at 5 or 10 cm talos-near-body-collision took 1-2 more median iterations.
ENV_SATURATION = 0.05


def center(state: Any, sphere: Point) -> Any:
    """Symbolic centre (3,) of a sphere in the frame of a kinematic state."""
    return state.p[sphere.joint_id] + state.R[sphere.joint_id] @ sphere.center


@dataclass
class Element:
    """One argument v of a row's smooth minimum, a function of sphere centres c_i, each
    separately: ``grads[i]`` = ∂v/∂c_i (3,), ``curvature[i]`` the (3, 3) block (i, i) of
    ∇²v - β∇v∇vᵀ (β = SOFT_MIN_BETA; no block between two centres); a constant has neither."""

    value: Any
    grads: dict[int, Any] = field(default_factory=dict)
    curvature: dict[int, Any] = field(default_factory=dict)


def box_element(c: Any, i: int, box: Any, radius: Any) -> Element:
    """v = LSE_β(s) - log(6)/β - r over the six face distances s = (l - h, -l - h) of the
    box-frame centre l = R_bᵀ(c - p_b) (see the module doc). With σ = softmax(βs) and
    a = σ⁺ - σ⁻ (3,), ∇_l v = a and ∇²_l v = β(diag(σ⁺ + σ⁻) - aaᵀ); in the world,
    ∇v = R_b a and ∇²v = R_b ∇²_l v R_bᵀ."""
    Rb, pb, h = ca.reshape(box[0:9], 3, 3), box[9:12], box[12:15]
    local = Rb.T @ (c - pb)
    s = ca.vertcat(local - h, -local - h)  # six face distances
    smax = ca.mmax(s)
    ex = ca.exp(BETA * (s - smax))
    total = ca.sum1(ex)
    v = smax + ca.log(total) / BETA - np.log(6.0) / BETA - radius
    plus, minus = ex[0:3] / total, ex[3:6] / total
    a = plus - minus
    grad = Rb @ a
    hess = Rb @ (BETA * (ca.diag(plus + minus) - a @ a.T)) @ Rb.T
    return Element(v, {i: grad}, {i: hess - SOFT_MIN_BETA * (grad @ grad.T)})


class _TwistSum:
    """Σ A_iᵀ X A_i (6, 6) over the spheres of a link, A = [I, -[ρ]×] the map from a link
    twist to the velocity of its point p + ρ: the four 3×3 blocks summed, the 6×6 made once."""

    def __init__(self) -> None:
        self.blocks: list[Any] = [0, 0, 0, 0]  # X, -X[ρ], [ρ]X, -[ρ]X[ρ]

    def add(self, X: Any, skew_i: Any) -> None:
        """Add A_iᵀ X A_i."""
        Y = -X @ skew_i
        for k, v in enumerate((X, Y, skew_i @ X, skew_i @ Y)):
            self.blocks[k] = self.blocks[k] + v

    def matrix(self) -> Any:
        """The 6×6 sum."""
        return _stack(self.blocks)


def _stack(blocks: list[Any]) -> Any:
    """[[B0, B1], [B2, B3]] (6, 6) from four 3×3 blocks (0 for an empty one)."""
    b = [ca.SX.zeros(3, 3) if isinstance(v, int) else v for v in blocks]
    return ca.vertcat(ca.horzcat(b[0], b[1]), ca.horzcat(b[2], b[3]))


def soft_min_rows(
    ctx: BuildContext,
    state: Any,
    spheres: list[Point],
    rows: list[list[Element]],
    margin: Any,
    base_rotation: Any,
) -> tuple[Any, Callable[[], BlockDerivatives]]:
    """Rows softmin_β(v_e) - margin over elements of sphere centres in ``state``, and their
    derivatives w.r.t. z (``CasadiKinematics.twist_jacobians``: z = qj for a state of fixed
    base, else (p_base, w, qj)).

    With weights w_e = softmax(-βv)_e and ḡ = Σ w_e ∇v_e, ∇row = ḡ and
    ∇²row = Σ w_e (∇²v_e - β∇v_e∇v_eᵀ) + βḡḡᵀ. Through the centres c_i = p_L + R_L s_i:
    ∂c_i/∂z = A_i J_L, so ∇²_z(λᵀrows) = Σ J_Lᵀ (A_iᵀ K A_j) J_L' (the curvature blocks
    summed per pair of links first), the rank-one terms βλḡḡᵀ (in z, or per centre for rows
    of one centre), and Σ_L ∇²_z(F_L·p_L + <G_L, R_L>) with the first-order weights
    f_i = Σ λ ∂row/∂c_i, F_L = Σ f_i, G_L = Σ f_i s_iᵀ held fixed. CasADi's own Hessian
    repeats each sphere pair's work once per colour of the Hessian's columns; this one does
    it once (Talos, 153 pairs: 74k instead of 117k instructions, tests/test_collision.py
    checks both equal). The derivatives are built when the returned function is called, that
    is only when a solver is built from the expressions: a structure whose library is in the
    disk cache does not pay for them."""
    values, soft = _soft_min_values(rows, margin)
    z = (
        ctx.joints
        if base_rotation is None
        else ca.vertcat(ctx.base_position, base_rotation, ctx.joints)
    )

    def build() -> BlockDerivatives:
        return _soft_min_derivatives(ctx, state, spheres, rows, soft, z, base_rotation)

    return ca.vertcat(*values), build


def _soft_min_values(rows: list[list[Element]], margin: Any) -> tuple[list[Any], list[Any]]:
    """Each row's softmin_β(v_e) - margin, and soft[k]: (exp(-β(v - min v)), its sum) of row
    k's smooth minimum (None for a row of one element)."""
    values, soft = [], []
    for elements in rows:
        v = ca.vertcat(*[e.value for e in elements])
        if len(elements) == 1:
            values.append(v - margin)
            soft.append(None)
        else:
            m = ca.mmin(v)
            ex = ca.exp(-SOFT_MIN_BETA * (v - m))
            total = ca.sum1(ex)
            values.append(m - ca.log(total) / SOFT_MIN_BETA - margin)
            soft.append((ex, total))
    return values, soft


@dataclass
class _Sums:
    """What the rows' derivatives accumulate (see :func:`soft_min_rows`)."""

    diag: dict[int, Any]  # Σ λ w K_ii per centre
    first: dict[int, Any]  # f_i = Σ λ ∂row/∂c_i
    jac_rows: list[Any]
    rank_one: Any  # Σ βλḡḡᵀ in z


def _soft_min_derivatives(
    ctx: BuildContext,
    state: Any,
    spheres: list[Point],
    rows: list[list[Element]],
    soft: list[Any],
    z: Any,
    base_rotation: Any,
) -> BlockDerivatives:
    """The rows' Jacobian and the Hessian of λᵀrows in z (see :func:`soft_min_rows`)."""
    lam = ca.SX.sym("lam", len(rows))
    link_of = {i: spheres[i].joint_id for row in rows for e in row for i in e.grads}
    J = ctx.kin.twist_jacobians(state, sorted(set(link_of.values())), base_rotation)
    rho = {i: state.R[L] @ spheres[i].center for i, L in link_of.items()}
    nz = next(iter(J.values())).shape[1] if J else 0
    sums = _Sums(
        {i: ca.SX.zeros(3, 3) for i in link_of},
        {i: ca.SX.zeros(3) for i in link_of},
        [],
        ca.SX(nz, nz),
    )
    for k, elements in enumerate(rows):
        _add_row(sums, k, elements, soft[k], lam, link_of, rho, J, nz)
    H = _curvature_hessian(sums, link_of, rho, J)
    Hk = kinematic_hessian(_link_weights(sums.first, link_of, spheres, J), state, J, z)
    if Hk is not None:
        H = H + Hk
    jac = ca.vertcat(*sums.jac_rows) if sums.jac_rows else ca.SX(0, nz)
    return BlockDerivatives(z=z, jacobian=jac, lam=lam, hessian=H)


def _add_row(
    sums: _Sums,
    k: int,
    elements: list[Element],
    soft_k: Any,
    lam: Any,
    link_of: dict[int, int],
    rho: dict[int, Any],
    J: dict[int, Any],
    nz: int,
) -> None:
    """Row k's gradient (a Jacobian row), curvature blocks, first-order weights and rank-one
    term, added to ``sums``."""
    if soft_k is None:
        weights: Any = [1.0]
    else:
        ex, total = soft_k
        weights = [ex[n] / total for n in range(len(elements))]
    gbar: dict[int, Any] = {}
    for e, w in zip(elements, weights, strict=True):
        for i, g in e.grads.items():
            gbar[i] = gbar.get(i, 0) + w * g
        for i, K in e.curvature.items():
            sums.diag[i] = sums.diag[i] + lam[k] * w * K
    wrench: dict[int, Any] = {}
    for i, g in gbar.items():
        sums.first[i] = sums.first[i] + lam[k] * g
        L = link_of[i]
        wrench[L] = wrench.get(L, 0) + ca.vertcat(g, ca.cross(rho[i], g))
    grad = ca.SX(nz, 1)
    for L, W in wrench.items():
        grad = grad + J[L].T @ W
    sums.jac_rows.append(grad.T)
    if len(gbar) == 1:
        ((i, g),) = gbar.items()
        sums.diag[i] = sums.diag[i] + lam[k] * SOFT_MIN_BETA * (g @ g.T)
    elif gbar:
        sums.rank_one = sums.rank_one + lam[k] * SOFT_MIN_BETA * (grad @ grad.T)


def _curvature_hessian(
    sums: _Sums, link_of: dict[int, int], rho: dict[int, Any], J: dict[int, Any]
) -> Any:
    """The rank-one terms and Σ J_Lᵀ (A_iᵀ K_i A_i) J_L over the curvature blocks, summed
    per link first."""
    blocks: dict[int, _TwistSum] = {}
    for i, D in sums.diag.items():
        blocks.setdefault(link_of[i], _TwistSum()).add(D, skew(rho[i]))
    H = sums.rank_one
    for L, M in blocks.items():
        H = H + J[L].T @ M.matrix() @ J[L]
    return H


def kinematic_hessian(
    weights: dict[int, tuple[Any, Any]], state: Any, J: dict[int, Any], z: Any
) -> Any:
    """Σ_L ∇²_z(F_L·p_L + <G_L, R_L>): the second derivatives of the kinematics weighted by
    the first-order ones (``weights[L]`` = (F_L (3,), G_L (3, 3)) held fixed; L over the
    links of J); None without links."""
    syms, vals, weighted = [], [], 0
    for L in sorted(J):
        F, G = ca.SX.sym(f"F{L}", 3), ca.SX.sym(f"G{L}", 3, 3)
        syms += [F, ca.vec(G)]
        vals += [weights[L][0], ca.vec(weights[L][1])]
        weighted = weighted + ca.dot(F, state.p[L]) + ca.sum1(ca.sum2(G * state.R[L]))
    if not syms:
        return None
    Hk = ca.hessian(weighted, z)[0]
    return ca.substitute(Hk, ca.vertcat(*syms), ca.vertcat(*vals))


def _link_weights(
    first: dict[int, Any], link_of: dict[int, int], spheres: list[Point], links: Any
) -> dict[int, tuple[Any, Any]]:
    """(F_L, G_L) = (Σ f_i, Σ f_i s_iᵀ) over the spheres i of each link L."""
    out = {}
    for L in links:
        mine = [i for i in first if link_of[i] == L]
        out[L] = (
            sum((first[i] for i in mine), ca.SX.zeros(3)),
            sum((first[i] @ spheres[i].center.T for i in mine), ca.SX.zeros(3, 3)),
        )
    return out


class Point(NamedTuple):
    """A sphere centre of a slot: its joint, and its centre in the joint's frame (3,), a
    parameter of the program."""

    joint_id: int
    center: Any
