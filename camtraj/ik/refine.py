"""Continuous refinement of a shot's track/extend curves inside the feasible corridor.

The variables are the track and extend values of every frame, x (n, 2) [m]; every other axis is
the closed-form solution on the frame's branch, so each frame reaches its pose exactly whatever
x is. The full :class:`ShotCost` (acceleration and jerk included) is lowered by damped
Gauss-Newton steps (Levenberg-Marquardt): per-frame 10 x 2 Jacobians of the measures by central
differences of the closed form (all frames in one call), finite differences of up to third order
between frames, so the normal matrix is banded (seven super-diagonals) and one banded Cholesky
solve gives the step. The L1 motion term enters through its majorising quadratic (iteratively
reweighted), the margin and overspeed hinges through their active sets. Each step is projected
into the corridor (the frame's track interval, then extend's reach interval at that track); a
frame the closed form cannot solve there keeps its previous values; a step is kept only if the
exact objective drops, so the result is never worse than its start.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from camtraj.ik.closed_form import EXTEND
from camtraj.ik.region import Region
from camtraj.ik.shot import branch_measures
from camtraj.ik.shot_cost import N_MEASURES, ShotCost
from camtraj.robot import Robot

Array = NDArray[np.float64]
IntArray = NDArray[np.intp]

_H = 1e-6  # [m] central-difference step of the Jacobian
_STENCILS = ((1, np.array([-1.0, 1.0])), (2, np.array([1.0, -2.0, 1.0])),
             (3, np.array([-1.0, 3.0, -3.0, 1.0])))
_GROUP = 4  # frames per block of the normal matrix (frames couple at most 3 apart)


@dataclass
class Refined:
    """The refined curves: x (n, 2) [m], measures y (n, 10), objective J, rounds taken."""

    x: Array
    y: Array
    cost: float
    rounds: int


class _Corridor:
    """Per frame: the chosen track interval and extend's reach interval at a track value."""

    def __init__(self, robot: Robot, targets: Array, lo1: Array, hi1: Array) -> None:
        self.lo1, self.hi1 = lo1, hi1
        self.region = Region(robot.dh, targets[:, :3, 3].T, -np.inf, np.inf,
                             float(robot.lower[EXTEND]), float(robot.upper[EXTEND]), 0.0)

    def project(self, x: Array) -> Array:
        r1 = np.clip(x[:, 0], self.lo1, self.hi1)
        lo4, hi4 = self.region.r4_interval(r1)
        r4 = np.clip(x[:, 1], lo4, np.maximum(lo4, hi4))
        return np.stack([r1, r4], axis=1)


def refine(robot: Robot, cost: ShotCost, targets: Array, branch: IntArray, x0: Array,
           y0: Array, lo1: Array, hi1: Array, rounds: int = 6) -> Refined:
    """Lower the shot objective from the start curves x0 (n, 2), measures y0 (n, 10).

    Args:
        robot: The robot.
        cost: The objective.
        targets: Flange poses (n, 4, 4) [m].
        branch: Closed-form branch per frame (n,).
        x0: Start track/extend per frame (n, 2) [m], feasible.
        y0: Its measures (n, 10), joints continuous.
        lo1, hi1: The track interval each frame stays in (n,) [m].
        rounds: Most Gauss-Newton steps (up to four times as many while a step between frames
            still exceeds a velocity limit).
    """
    n = x0.shape[0]
    corridor = _Corridor(robot, targets, lo1, hi1)
    x, y = x0.copy(), y0.copy()
    j = cost.total(y)
    mu = 1e-3
    taken = 0
    if n < 2:
        return Refined(x, y, j, 0)
    targets3 = np.concatenate([targets] * 3)
    b3 = np.tile(branch, 3)
    rel = 0.0
    for rnd in range(4 * rounds):
        # measures at x + h e_track and x + h e_extend (x itself is known), one closed-form
        # call; a side the closed form cannot solve (a corridor edge) is taken backwards
        grad_y = np.zeros((n, N_MEASURES, 2))
        side = np.ones((n, 2))
        for _attempt in range(2):
            pts = np.concatenate([x, x + [_H, 0] * side[:, :1], x + [0, _H] * side[:, 1:]])
            prev = np.concatenate([y[:, :8]] * 3)
            ya, oka = branch_measures(robot, targets3, pts[:, 0], pts[:, 1], prev, b3)
            ys = ya.reshape(3, n, N_MEASURES)
            oks = oka.reshape(3, n)
            for v in range(2):
                good = oks[v + 1][:, None]
                grad_y[:, :, v] = np.where(good, (ys[v + 1] - y) / (_H * side[:, v:v + 1]),
                                           grad_y[:, :, v])
            bad = ~oks[1:].T  # (n, 2)
            if not bad.any() or _attempt:
                break
            side = np.where(bad, -1.0, side)
        H, g = _normal_equations(cost, y, grad_y)
        improved = False
        for _try in range(6):
            step = _solve_banded(H, g, mu)
            xn = corridor.project(x + step)
            yn, keep = branch_measures(robot, targets, xn[:, 0], xn[:, 1], y[:, :8], branch)
            xn = np.where(keep[:, None], xn, x)
            yn = np.where(keep[:, None], yn, y)
            jn = cost.total(yn)
            if jn < j:
                improved = True
                rel = (j - jn) / max(abs(j), 1e-300)
                x, y, j = xn, yn, jn
                mu = max(mu / 3.0, 1e-9)
                break
            mu *= 10.0
        taken += 1
        if not improved:
            break
        # beyond ``rounds`` only while a step still exceeds a velocity limit (up to 4x as many)
        fast = bool(np.any(np.abs(np.diff(y[:, :8], axis=0)) > cost.vel))
        if rel < 1e-4 or (rnd + 1 >= rounds and not fast):
            break
    return Refined(x, y, j, taken)


def _normal_equations(cost: ShotCost, y: Array, grad_y: Array) -> tuple[list[Array], Array]:
    """Gauss-Newton normal matrix (as 2 x 2 blocks on block diagonals 0..3) and gradient.

    The difference terms are first gathered per axis in the joints: ``M[d][p, i]`` is the
    curvature coupling frames p and p + d through axis i, ``gq`` the gradient in the joints;
    then the chain rule through the per-frame Jacobians (n, 10, 2) gives the blocks.
    """
    n = y.shape[0]
    H = [np.zeros((n, 2, 2)) for _ in range(4)]
    M = [np.zeros((n, 8)) for _ in range(4)]
    gq = np.zeros((n, 8))
    q, G = y[:, :8], grad_y[:, :8, :]
    for order, stencil in _STENCILS:
        m = n - order
        if m <= 0:
            continue
        if order == 1:
            z = np.diff(q, axis=0) / cost.vel
            a = np.abs(z)
            over = np.maximum(a - 1.0, 0.0)
            sign = np.sign(z)
            dz = 2 * cost.velocity * z + 2 * cost.overspeed * over * sign + cost.motion_coef * sign
            ddz = (2 * cost.velocity + 2 * cost.overspeed * (over > 0)
                   + cost.motion_coef / np.maximum(a, 0.05))
            scale = cost.vel
        elif order == 2:
            z = np.diff(q, 2, axis=0) / cost.acc
            dz, ddz = 2 * cost.acceleration * z, np.full_like(z, 2 * cost.acceleration)
            scale = cost.acc
        else:
            z = np.diff(q, 3, axis=0) / cost.jerk
            dz, ddz = 2 * cost.jerk_weight * z, np.full_like(z, 2 * cost.jerk_weight)
            scale = cost.jerk
        dz, w = dz / scale, ddz / (scale * scale)
        for ia, ca in enumerate(stencil):
            gq[ia:ia + m] += ca * dz
            for ib in range(ia, stencil.size):
                M[ib - ia][ia:ia + m] += (ca * stencil[ib]) * w
    g = np.einsum("ki,kip->kp", gq, G)
    for d in range(4):
        if n - d <= 0:
            continue
        Ga, Gb = M[d][: n - d, :, None] * G[: n - d], G[d:]
        H[d][: n - d] = np.einsum("kip,kiq->kpq", Ga, Gb)
    # margins: hinge^2 of z = 1 - d / zone, d the distance to the nearer limit (or the
    # singularity distance itself)
    e = cost.intrusion(y)
    active = e > 0
    if active.any():
        lower_near = (y[:, :8] - cost.lower) <= (cost.upper - y[:, :8])
        dd = np.concatenate([np.where(lower_near, 1.0, -1.0), np.ones((n, 2))], axis=1)
        dz = -dd / cost.zone  # dz/dy
        gz = np.where(active, 2 * cost.margin * e * dz, 0.0)
        hz = np.where(active, 2 * cost.margin * dz * dz, 0.0)
        g += np.einsum("ki,kip->kp", gz, grad_y)
        H[0] += np.einsum("ki,kip,kiq->kpq", hz, grad_y, grad_y)
    if n > 1:  # run-up / run-out room: frames (0, 1) and (n - 1, n - 2)
        for edge, inner in ((0, 1), (n - 1, n - 2)):
            p, slope = cost.edge_excursion(q[edge], q[inner])
            e = cost.edge_intrusion(p)
            if not (e > 0).any():
                continue
            lower_near = (p - cost.lower) <= (cost.upper - p)
            de = np.where(e > 0, -np.where(lower_near, 1.0, -1.0) / cost.zone[:8], 0.0)
            ge, he = 2 * cost.margin * e * de, 2 * cost.margin * de * de
            a_e = slope[:, None] * G[edge]  # dp/dx_edge (8, 2)
            a_i = (1.0 - slope)[:, None] * G[inner]
            g[edge] += ge @ a_e
            g[inner] += ge @ a_i
            H[0][edge] += (he[:, None, None] * a_e[:, :, None] * a_e[:, None, :]).sum(axis=0)
            H[0][inner] += (he[:, None, None] * a_i[:, :, None] * a_i[:, None, :]).sum(axis=0)
            lo_f = min(edge, inner)
            a_lo, a_hi = (a_e, a_i) if edge < inner else (a_i, a_e)
            H[1][lo_f] += (he[:, None, None] * a_lo[:, :, None] * a_hi[:, None, :]).sum(axis=0)
    return H, g


def _solve_banded(H: list[Array], g: Array, mu: float) -> Array:
    """Solve (H + mu diag(H) + eps I) step = -g for the (n, 2) step.

    ``H[d][i]`` is the 2x2 block coupling frame i with frame i + d (d = 0..3; the d = 0 blocks
    are symmetric). Grouping four frames makes the matrix block tridiagonal (8x8 blocks:
    frames couple at most three apart), solved by block elimination (the symmetric positive
    definite block Thomas algorithm): a few small numpy calls per group, and no scipy import
    on the first solve of a process (which costs more than every later solve together).
    """
    n = g.shape[0]
    groups = -(-n // _GROUP)
    m = groups * _GROUP  # frames, padded with unit rows (step 0) to whole groups
    diag_blocks = np.zeros((groups, 2 * _GROUP, 2 * _GROUP))
    upper_blocks = np.zeros((groups, 2 * _GROUP, 2 * _GROUP))
    for d, blk in enumerate(H):
        i = np.arange(n - d)
        j = i + d
        gi, gj = i // _GROUP, j // _GROUP
        ri, cj = 2 * (i % _GROUP), 2 * (j % _GROUP)
        for r in range(2):
            for s in range(2):
                vals = blk[: n - d, r, s]
                same = gi == gj
                np.add.at(diag_blocks, (gi[same], ri[same] + r, cj[same] + s), vals[same])
                if d > 0:  # the lower triangle of a diagonal block, by symmetry
                    np.add.at(diag_blocks, (gi[same], cj[same] + s, ri[same] + r), vals[same])
                    nxt = ~same
                    np.add.at(upper_blocks, (gi[nxt], ri[nxt] + r, cj[nxt] + s), vals[nxt])
    size = 2 * _GROUP
    eye = np.arange(size)
    diag = diag_blocks[:, eye, eye].reshape(-1)[: 2 * n]
    shift = 1e-9 * max(float(diag.max()), 1e-12) + 1e-12
    damped = diag_blocks[:, eye, eye] * (1.0 + mu) + shift
    pad = np.arange(2 * n, 2 * m)
    damped.reshape(-1)[pad] = 1.0  # padding unknowns: 1 * step = 0
    diag_blocks[:, eye, eye] = damped
    rhs = np.zeros(2 * m)
    rhs[: 2 * n] = -g.ravel()
    b = rhs.reshape(groups, size)
    w = np.zeros_like(upper_blocks)  # C_k^-1 U_k
    z = np.zeros_like(b)  # C_k^-1 y_k
    c_k, y_k = diag_blocks[0], b[0]
    for k in range(groups):
        if k > 0:
            u_t = upper_blocks[k - 1].T
            c_k = diag_blocks[k] - u_t @ w[k - 1]
            y_k = b[k] - u_t @ z[k - 1]
        sol = np.linalg.solve(c_k, np.column_stack([upper_blocks[k], y_k]))
        w[k], z[k] = sol[:, :size], sol[:, size]
    x = np.empty_like(b)
    x[-1] = z[-1]
    for k in range(groups - 2, -1, -1):
        x[k] = z[k] - w[k] @ x[k + 1]
    return x.reshape(-1)[: 2 * n].reshape(n, 2)


__all__ = ["Refined", "refine"]
