"""What the collision rows share: the smooth minimum's sharpness, the smooth sphere-box
distance (:func:`box_element`), links' twist Jacobians on their chains (:func:`compressed`),
results added where their indices say (:func:`scatter_sum`), work mapped over slots
(:func:`map_columns`) and done only where it is needed (:func:`gated`), and the kinematics'
second derivatives weighted by first-order ones (:func:`kinematic_hessian`). The rows themselves:
:mod:`posturegen.collision.self_blocks` (self), :mod:`posturegen.collision.env_slots`
(sphere-box)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import casadi as ca
import numpy as np

from .boxes import BETA
from .native import native

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


class BoxElement(NamedTuple):
    """A sphere's smooth distance v to a box, its gradient ∂v/∂c (3,) in the centre and the
    curvature ∇²_c v - β∇_c v∇_c vᵀ (3, 3) (β = SOFT_MIN_BETA)."""

    value: Any
    grad: Any
    curvature: Any


def box_element(c: Any, box: Any, radius: Any) -> BoxElement:
    """v = LSE_β(s) - log(6)/β - r over the six face distances s = (l - h, -l - h) of the
    box-frame centre l = R_bᵀ(c - p_b), ``box`` (15,) = (R_b column-major, p_b, h). With
    σ = softmax(βs) and a = σ⁺ - σ⁻ (3,), ∇_l v = a and ∇²_l v = β(diag(σ⁺ + σ⁻) - aaᵀ); in
    the world, ∇v = R_b a and ∇²v = R_b ∇²_l v R_bᵀ."""
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
    return BoxElement(v, grad, hess - SOFT_MIN_BETA * (grad @ grad.T))


def gated(heavy: ca.Function, when: Callable[[list[Any]], Any] | None = None) -> ca.Function:
    """``heavy`` behind a switch: zeros, without evaluating it, unless ``when(args)`` (default:
    its first argument is not 0). A branch of the generated C; CasADi's SX would evaluate
    both sides of an if_else, hence a switch inside an MX function that is never inlined."""
    zero = ca.Function(
        f"{heavy.name()}_zero",
        [ca.SX.sym(f"i{k}", heavy.sparsity_in(k)) for k in range(heavy.n_in())],
        [ca.SX.zeros(heavy.sparsity_out(k).shape) for k in range(heavy.n_out())],
    )
    switch = ca.Function.conditional(f"{heavy.name()}_switch", [zero], heavy)
    args = [ca.MX.sym(f"i{k}", heavy.sparsity_in(k)) for k in range(heavy.n_in())]
    condition = args[0] != 0 if when is None else when(args)
    outs = switch(condition, *args)
    outs = list(outs) if isinstance(outs, (list, tuple)) else [outs]
    return ca.Function(f"{heavy.name()}_gated", args, outs, {"never_inline": True})


def switched(heavy: ca.Function, compiled: bool = False) -> ca.Function:
    """(index, *heavy's arguments) -> ``heavy``'s outputs when index is 1, zeros (without
    evaluating it) when 0: a switch, a branch of the generated C, whose outputs land where
    its caller wants them (a map's columns: no copy). ``compiled``: ``heavy`` in machine
    code on the virtual machine (:func:`posturegen.collision.native.native`)."""
    if compiled:
        heavy = native(heavy)
    zero = ca.Function(
        f"{heavy.name()}_zero",
        [ca.SX.sym(f"i{k}", heavy.sparsity_in(k)) for k in range(heavy.n_in())],
        [ca.SX.zeros(heavy.sparsity_out(k).shape) for k in range(heavy.n_out())],
    )
    return ca.Function.conditional(f"{heavy.name()}_switch", [zero], heavy)


def compressed(jacobians: list[Any], columns: list[list[int]], width: int) -> Any:
    """(6·width·N,) the Jacobians' chain columns, each padded with zero columns to ``width``,
    link after link (column-major)."""
    return ca.vertcat(
        *[
            ca.vec(ca.horzcat(ca.densify(J[:, cols]), ca.SX.zeros(6, width - len(cols))))
            for J, cols in zip(jacobians, columns, strict=True)
        ]
    )


def scatter_sum(size: int, values: Any, index: Any) -> Any:
    """(size,) the sum of ``values`` at the indices ``index`` (MX expressions of one shape):
    repeated indices add up, an index out of range (a chain's padding) is dropped. The
    transpose of a gather (CasADi's reverse mode of it), a loop ``w[i] += v`` in the
    generated C."""
    x = ca.MX.sym("x", size)
    return ca.jtimes(x.get_nz(False, ca.vec(index)), x, ca.vec(values), True)


def map_columns(fn: ca.Function, n: int) -> ca.Function:
    """``fn`` over n columns of each of its inputs and outputs (a loop in the generated C,
    whose code does not grow with n): every input is given per column, none shared (a map's
    shared inputs are copied once per column)."""
    return fn.map(n, "serial")


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
