"""The largest ellipse inscribed in the intersection of two convex polygons
(:func:`largest_inscribed_ellipse`): ``max log rx + log ry`` under the per-edge rows of
:mod:`posturegen.model.ellipse_rows`, solved with IPOPT (a warm path-following start, else a
cold solve in the frame normalized by the intersection's moments)."""

from __future__ import annotations

import math
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from .._cache import BoundedCache
from ..errors import InputError, PosturegenError
from .ellipse_rows import _BUILDERS
from .geometry import (
    ConvexPolygon,
    Ellipse,
    FloatArray,
    Formulation,
    PolygonLike,
    _as_polygon,
    _cross2,
    _polygon_covariance,
    intersect,
)

__all__ = ["largest_inscribed_ellipse"]

_R_MIN = 1e-6  # lower bound on rx, ry in normalized units (intersection of size ~1)
_START = (0.95, 0.9)  # initial radii as fractions of the centroid's edge margin
_SOLVER_CACHE: BoundedCache[ca.Function] = BoundedCache("ellipse solvers", 64)
_IPOPT_OPTS: dict[str, Any] = {
    "print_time": False,
    "ipopt.print_level": 0,
    "ipopt.sb": "yes",
    "ipopt.tol": 1e-10,
    "ipopt.acceptable_tol": 1e-7,
    "ipopt.constr_viol_tol": 1e-10,
    "ipopt.bound_relax_factor": 1e-10,
    "ipopt.max_iter": 300,
}


def _solver(formulation: str, n1: int, n2: int) -> ca.Function:
    """IPOPT solver (cached) for ``max log rx + log ry`` s.t. ellipse in P1 and P2 (params)."""
    key = (formulation, n1, n2)
    solver = _SOLVER_CACHE.get(key)
    if solver is not None:
        return solver
    x = ca.SX.sym("x", 5)
    p = ca.SX.sym("p", 2 * (n1 + n2))
    V1 = ca.reshape(p[: 2 * n1], 2, n1).T
    V2 = ca.reshape(p[2 * n1 :], 2, n2).T
    build = _BUILDERS[formulation]
    g = build(V1, x[0], x[1], x[2], x[3], x[4]) + build(V2, x[0], x[1], x[2], x[3], x[4])
    nlp = {"x": x, "p": p, "f": -(ca.log(x[3]) + ca.log(x[4])), "g": ca.vertcat(*g)}
    solver = ca.nlpsol(f"lie_{formulation}_{n1}_{n2}", "ipopt", nlp, _IPOPT_OPTS)
    _SOLVER_CACHE[key] = solver
    return solver


def largest_inscribed_ellipse(
    P1: PolygonLike, P2: PolygonLike, formulation: Formulation = "support"
) -> Ellipse:
    """Maximum-area ellipse in ``P1 ∩ P2``: ``max log rx + log ry`` s.t. ``g_k <= 0`` on all edges.

    The constraints are the symbolic builders of ``formulation`` ("paper" eq. 6 or "support"),
    one per edge of ``P1`` and of ``P2``, solved with IPOPT (exact Hessian).  The problem is first
    normalized by the affine map ``y = M (x - c)`` (``c`` the centroid and ``M = 1/2 S^(-1/2)``
    with ``S`` the second moment of ``P1 ∩ P2``), which maps ellipses to ellipses and preserves
    area ratios, so thin, tiny or skewed intersections become unit-size and round.  The result
    is mapped back and returned with ``rx >= ry`` and ``angle`` in ``(-pi/2, pi/2]``.

    Raises :class:`InputError` for invalid polygons or an empty intersection and
    :class:`PosturegenError` if IPOPT fails or the ellipse is not inside both polygons.
    """
    if formulation not in _BUILDERS:
        raise InputError(
            "formulation", f"unknown formulation {formulation!r}", "use 'paper' or 'support'"
        )
    A = _as_polygon(P1, "P1")
    B = _as_polygon(P2, "P2")
    ell = _warm_solve(A, B, formulation)
    return ell if ell is not None else _cold_solve(A, B, formulation)


def _mapped_ellipse(xs: FloatArray, Minv: FloatArray, centre: FloatArray) -> Ellipse:
    """The ellipse of a solution xs = (cx, cy, θ, rx, ry) of a normalized frame, its shape
    mapped back by Minv (2, 2), centred at ``centre``: rx >= ry, angle in (-π/2, π/2]."""
    ct, st = math.cos(xs[2]), math.sin(xs[2])
    shape = Minv @ np.array([[ct * xs[3], -st * xs[4]], [st * xs[3], ct * xs[4]]])
    Us, sv, _ = np.linalg.svd(shape)
    angle = math.atan2(Us[1, 0], Us[0, 0])
    if angle <= -math.pi / 2:
        angle += math.pi
    elif angle > math.pi / 2:
        angle -= math.pi
    return Ellipse(center=centre, angle=angle, radii=(float(sv[0]), float(sv[1])))


# theta is only defined modulo pi (modulo pi/2 with rx <-> ry) and _cold_solve leaves it
# unbounded: when the normalized optimum is nearly round the theta-curvature (~ (rx - ry)^2)
# vanishes, IPOPT takes long theta steps and any finite box (tried: [-pi, pi], th0 +- 2 pi)
# becomes active at a spurious KKT point. cos/sin make the problem periodic anyway; the
# returned angle is wrapped to (-pi/2, pi/2] with rx >= ry.
def _cold_solve(A: ConvexPolygon, B: ConvexPolygon, formulation: Formulation) -> Ellipse:
    """IPOPT from a centred circle in the frame normalized by the intersection's moments."""
    inter = intersect(A, B)
    if inter is None:
        raise InputError(
            "P1, P2",
            "the polygons do not intersect (empty or zero-area intersection)",
            "move the patches so that they overlap",
        )
    c0 = inter.centroid
    S = _polygon_covariance(inter.vertices, c0, inter.area)
    w, U = np.linalg.eigh(S)
    M = U @ np.diag(0.5 / np.sqrt(w)) @ U.T  # y = M (x - c0)
    Minv = U @ np.diag(2.0 * np.sqrt(w)) @ U.T
    V1 = (A.vertices - c0) @ M.T
    V2 = (B.vertices - c0) @ M.T
    Vi = (inter.vertices - c0) @ M.T

    # initial guess: an ellipse strictly inside the largest centred circle, along principal axes
    ei = np.roll(Vi, -1, axis=0) - Vi
    r0 = float(np.min(np.abs(_cross2(ei, -Vi)) / np.linalg.norm(ei, axis=1)))
    cov = np.cov(Vi.T)
    _, Uv = np.linalg.eigh(cov)
    th0 = math.atan2(Uv[1, 1], Uv[0, 1])
    th0 = (th0 + math.pi / 2) % math.pi - math.pi / 2
    x0 = [0.0, 0.0, th0, _START[0] * r0, _START[1] * r0]

    # valid box: the centre lies in the intersection and no radius exceeds its diameter;
    # it keeps the paper form (whose g ~ 1/(rx ry) flattens for huge ellipses) from drifting off
    lo, hi = Vi.min(axis=0), Vi.max(axis=0)
    rmax = float(np.linalg.norm(hi - lo))
    solver = _solver(formulation, A.n, B.n)
    sol = solver(
        x0=x0,
        p=np.concatenate([V1.ravel(), V2.ravel()]),
        # theta unbounded: see above
        lbx=[lo[0], lo[1], -math.inf, _R_MIN, _R_MIN],
        ubx=[hi[0], hi[1], math.inf, rmax, rmax],
        lbg=-np.inf,
        ubg=0.0,
    )
    status = solver.stats()["return_status"]
    if status not in ("Solve_Succeeded", "Solved_To_Acceptable_Level"):
        raise PosturegenError(f"largest_inscribed_ellipse: IPOPT failed ({status})")
    xs = np.asarray(sol["x"]).ravel()
    ell = _mapped_ellipse(xs, Minv, c0 + Minv @ xs[:2])
    scale = math.sqrt(inter.area)
    m = min(ell.inside_margin(A), ell.inside_margin(B))
    if m < -1e-7 * scale:
        raise PosturegenError(
            f"largest_inscribed_ellipse: solution leaves the polygons (margin {m:.3g})"
        )
    return ell


# ---------------------------------------------------------------------------------------------
# Warm start: the central path of the convex form, then IPOPT certifies
# ---------------------------------------------------------------------------------------------
# The convex form of the same problem (E = {B w + d : |w| <= 1}, B symmetric positive):
#   max log det B  s.t.  |B a_k| <= b_k - a_k.d,
# whose barrier  t·(-log det B) - Σ log((b_k - a_k.d)² - |B a_k|²)  is self-concordant, so
# damped Newton steps z -= H⁻¹∇/(1 + λ) stay feasible for any polygon shape. A fixed schedule of
# _PATH_STEPS values of t (two steps each) runs as one cached CasADi function; the result, a
# point within ~ν/t of the optimum, is mapped to the frame where the ellipse is the unit circle
# and handed to IPOPT with multipliers λ_k = 1/(t·(-g_k)), so IPOPT only has to certify it.
_PATH_STEPS, _PATH_KAPPA = 24, 2.5  # t from 1 to 2.5^23 ≈ 1.4e9: IPOPT certifies in 1 iteration
_T_FINAL = _PATH_KAPPA ** (_PATH_STEPS - 1)
_PATH_CACHE: BoundedCache[ca.Function] = BoundedCache("ellipse central paths", 64)
_WARM_CACHE: BoundedCache[ca.Function] = BoundedCache("ellipse warm solvers", 64)
_WARM_OPTS: dict[str, Any] = {
    **_IPOPT_OPTS,
    "ipopt.warm_start_init_point": "yes",
    "ipopt.mu_init": 1e-9,
    "ipopt.warm_start_bound_push": 1e-9,
    "ipopt.warm_start_bound_frac": 1e-9,
    "ipopt.warm_start_slack_bound_push": 1e-9,
    "ipopt.warm_start_slack_bound_frac": 1e-9,
    "ipopt.warm_start_mult_bound_push": 1e-9,
    "ipopt.max_iter": 50,
    "ipopt.tol": 1e-8,  # from the path's point (duality gap ~1e-8) IPOPT needs 1 iteration
    "error_on_fail": True,  # a failure raises (cheaper than reading the stats on success)
}


def _central_path(m: int) -> ca.Function:
    """(z0 (5,), A (m, 2), b (m,)) -> (z (5,) = (d, b11, b12, b22) near the optimum, the last
    Newton decrement λ: small when z is on the central path)."""
    f = _PATH_CACHE.get(m)
    if f is not None:
        return f
    z, A, b, t = ca.SX.sym("z", 5), ca.SX.sym("A", m, 2), ca.SX.sym("b", m), ca.SX.sym("t")
    Bm = ca.vertcat(ca.horzcat(z[2], z[3]), ca.horzcat(z[3], z[4]))
    s = b - A @ z[0:2]
    phi = -t * ca.log(z[2] * z[4] - z[3] ** 2) - ca.sum1(ca.log(s**2 - ca.sum2((A @ Bm) ** 2)))
    grad = ca.gradient(phi, z)
    dz = ca.solve(ca.hessian(phi, z)[0], grad)
    lam = ca.sqrt(ca.fmax(ca.dot(grad, dz), 0))
    step = ca.Function("step", [z, A, b, t], [z - dz / (1 + lam), lam])
    zm, Am, bm = ca.MX.sym("z", 5), ca.MX.sym("A", m, 2), ca.MX.sym("b", m)
    zz, lam_last = zm, None
    for k in range(_PATH_STEPS):
        tk = _PATH_KAPPA**k
        for _ in range(2):
            zz, lam_last = step(zz, Am, bm, tk)
    f = ca.Function(f"central_path_{m}", [zm, Am, bm], [zz, lam_last])
    _PATH_CACHE[m] = f
    return f


_PATH_Z0 = np.array([0.0, 0.0, 0.9, 0.0, 0.9])  # a circle inside the unit margin
_WARM_X0 = np.array([0.0, 0.0, 0.0, 1.0, 2.0])  # the path's ellipse in the y frame
_WARM_LBX = np.array([-4.0, -4.0, -math.inf, _R_MIN, _R_MIN])
_WARM_UBX = np.array([4.0, 4.0, math.inf, 8.0, 8.0])
_NEXT_CACHE: BoundedCache[NDArray[np.intp]] = BoundedCache("ellipse edge indices", 64)


def _next_index(n1: int, n2: int) -> NDArray[np.intp]:
    """Index of each vertex's successor in the stacked vertices of two polygons."""
    key = (n1, n2)
    if key not in _NEXT_CACHE:
        _NEXT_CACHE[key] = np.concatenate(
            [np.arange(1, n1 + 1) % n1, n1 + np.arange(1, n2 + 1) % n2]
        )
    return _NEXT_CACHE[key]


def _warm_solver(formulation: str, n1: int, n2: int) -> ca.Function:
    key = (formulation, n1, n2)
    if key not in _WARM_CACHE:
        x = ca.SX.sym("x", 5)
        p = ca.SX.sym("p", 2 * (n1 + n2))
        V1 = ca.reshape(p[: 2 * n1], 2, n1).T
        V2 = ca.reshape(p[2 * n1 :], 2, n2).T
        build = _BUILDERS[formulation]
        g = build(V1, *[x[i] for i in range(5)]) + build(V2, *[x[i] for i in range(5)])
        nlp = {"x": x, "p": p, "f": -(ca.log(x[3]) + ca.log(x[4])), "g": ca.vertcat(*g)}
        _WARM_CACHE[key] = ca.nlpsol(f"lie_warm_{formulation}_{n1}_{n2}", "ipopt", nlp, _WARM_OPTS)
    return _WARM_CACHE[key]


def _interior_point(A: ConvexPolygon, B: ConvexPolygon) -> FloatArray | None:
    """A point strictly inside A ∩ B, or None: the mean of the intersection polygon's vertices
    (the vertices of each polygon inside the other and the crossings of their edges)."""
    nA, bA = A.halfplanes()
    nB, bB = B.halfplanes()
    va, vb = A.vertices, B.vertices
    pts = [va[np.all(va @ nB.T <= bB, axis=1)], vb[np.all(vb @ nA.T <= bA, axis=1)]]
    # crossings of edge i of A (p + s·r) with edge j of B (q + u·w), s, u in [0, 1]
    r = np.roll(va, -1, axis=0) - va
    w = np.roll(vb, -1, axis=0) - vb
    den = r[:, None, 0] * w[None, :, 1] - r[:, None, 1] * w[None, :, 0]  # (nA, nB)
    qp = vb[None, :, :] - va[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        s_ = (qp[..., 0] * w[None, :, 1] - qp[..., 1] * w[None, :, 0]) / den
        u_ = (qp[..., 0] * r[:, None, 1] - qp[..., 1] * r[:, None, 0]) / den
    hit = (np.abs(den) > 1e-15) & (s_ >= 0) & (s_ <= 1) & (u_ >= 0) & (u_ <= 1)
    pts.append(va[np.nonzero(hit)[0]] + s_[hit][:, None] * r[np.nonzero(hit)[0]])
    v = np.vstack(pts)
    return v.mean(axis=0) if len(v) >= 3 else None


def _quick_interior_point(A: ConvexPolygon, B: ConvexPolygon) -> FloatArray | None:
    """The first of (midpoint of the centroids, centroid of A, centroid of B) strictly inside
    both polygons with a margin of 1 % of the smaller one's size, or the general method."""
    nA, bA = A.halfplanes()
    nB, bB = B.halfplanes()
    cands = np.array([0.5 * (A.centroid + B.centroid), A.centroid, B.centroid])  # (3, 2)
    margin = np.minimum((bA - cands @ nA.T).min(axis=1), (bB - cands @ nB.T).min(axis=1))
    k = int(np.argmax(margin))
    if margin[k] > 0.01 * math.sqrt(min(A.area, B.area)):
        return cands[k]
    return _interior_point(A, B)


def _warm_solve(A: ConvexPolygon, B: ConvexPolygon, formulation: Formulation) -> Ellipse | None:
    """The fast path; None when it cannot certify (the cold path then decides)."""
    p0 = _quick_interior_point(A, B)
    if p0 is None:
        return None
    (nA, bA), (nB, bB) = A.halfplanes(), B.halfplanes()
    normals = np.vstack([nA, nB])
    offsets = np.concatenate([bA, bB]) - normals @ p0
    r0 = float(offsets.min())
    if not r0 > 1e-12 * max(1.0, float(np.abs(offsets).max())):
        return None
    z_dm, decrement = _central_path(len(offsets))(_PATH_Z0, normals, offsets / r0)
    z = np.asarray(z_dm).ravel()
    Bs = np.array([[z[2], z[3]], [z[3], z[4]]])
    det_path = float(np.linalg.det(Bs))
    # far off the central path (many edges need more Newton steps than the fixed schedule;
    # measured: λ ≈ 2-4 for 3-6 sided pairs, 5e4 for two 32-gons): the multipliers below would
    # be poor, so leave it to the cold start
    if not np.all(np.isfinite(z)) or det_path <= 0 or Bs[0, 0] <= 0 or float(decrement) > 10:
        return None
    # y = M (x' - d), x' = (x - p0)/r0, M = diag(1/σ1, 2/σ2)·Rᵀ for Bs = R diag(σ) Rᵀ: the
    # path's ellipse becomes axis-aligned with radii (1, 2), never round (θ stays well posed)
    sig, R = np.linalg.eigh(Bs)
    if np.linalg.det(R) < 0:  # a rotation, so the polygons stay counter-clockwise
        R[:, 1] = -R[:, 1]
    M = np.diag([1.0 / sig[0], 2.0 / sig[1]]) @ R.T
    Minv = R @ np.diag([sig[0], 0.5 * sig[1]])
    V = ((np.vstack([A.vertices, B.vertices]) - p0) / r0 - z[:2]) @ M.T  # both, in y
    nxt = _next_index(A.n, B.n)
    e = V[nxt] - V
    le = np.sqrt(np.einsum("ij,ij->i", e, e))
    n = np.column_stack([e[:, 1], -e[:, 0]]) / le[:, None]  # outward unit normals
    b = np.einsum("ij,ij->i", n, V)  # offsets, the centre being 0
    u = np.hypot(n[:, 0], 2.0 * n[:, 1])  # support of the (1, 2) ellipse
    if np.any(b - u <= 0):
        return None
    lam = 2.0 * b / (_T_FINAL * (b**2 - u**2))  # central-path multipliers of the rows
    if formulation == "paper":
        lam = lam * 2.0 / le  # g_paper = g_support·|e|/(rx·ry), here rx·ry = 2
    solver = _warm_solver(formulation, A.n, B.n)
    try:
        sol = solver(
            x0=_WARM_X0, p=V.ravel(), lbx=_WARM_LBX, ubx=_WARM_UBX, lbg=-np.inf, ubg=0.0, lam_g0=lam
        )
    except RuntimeError:  # error_on_fail: IPOPT did not converge from the warm start
        return None
    xs = np.asarray(sol["x"]).ravel()
    ell = _mapped_ellipse(xs, r0 * Minv, p0 + r0 * (z[:2] + Minv @ xs[:2]))
    if min(ell.inside_margin(A), ell.inside_margin(B)) < -1e-7 * r0:
        return None
    # the path's ellipse is feasible: a KKT point of IPOPT smaller than it is a spurious one
    # (the (c, θ, rx, ry) form is not convex), so leave it to the cold start
    if ell.area < math.pi * det_path * r0**2 * (1 - 1e-7):
        return None
    return ell
