"""Inverse kinematics: joint angles that put the tool at a pose (pure numpy, no I/O).

Damped least squares in the Levenberg-Marquardt form of Sugihara (2011): each step solves
``(JᵀWJ + λI) Δq = JᵀWe`` with ``λ = ½eᵀWe + λ₀``, so the damping is large far from the
target (a short, safe gradient step) and vanishes at it (Gauss-Newton, quadratic
convergence to 1e-3 mm / 1e-6 rad in a few steps). Only the *active* joints take part: a
locked joint (the LWA 3's j3) is folded into the fixed geometry at its locked value, so it
can never move. After every step the joints are brought back inside their limits (a
full-turn joint wraps, the others are clamped).

With more active joints than the six of a pose (the full 7-joint arm) the remaining
freedom (elbow swivel) is spent moving towards the seed: a null-space step
``(I - J⁺J)·k·(q_seed - q)`` that does not disturb the pose.

The seed (the current configuration, or a named one) is tried first, so the solution is
the one nearest to it in the usual case; if it does not converge, further seeds are tried,
first near the seed, then spread over the joint ranges (deterministic). When none
converges the target is :class:`Unreachable`, with the smallest residual found.

Angles here are radians in user coordinates (Totem = zeros), lengths millimetres.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from seqrun.arm.description import ArmDescription
from seqrun.errors import SeqrunError
from seqrun.arm.kinematics import Chain, frame_matrix, matrix_from_rpy

if TYPE_CHECKING:  # annotations only: numpy.typing is an import of its own at run time
    import numpy.typing as npt

__all__ = [
    "ANGLE_TOLERANCE_RAD",
    "POSITION_TOLERANCE_MM",
    "IkSolution",
    "IkSolver",
    "Unreachable",
    "target_frame",
    "tool_chain",
]

#: A solution puts the tool within these of the target (the benchmark's criterion).
POSITION_TOLERANCE_MM = 1e-3
ANGLE_TOLERANCE_RAD = 1e-6
#: Length (mm) that weighs one radian of orientation error against millimetres of position.
ORIENTATION_WEIGHT_MM = 200.0
#: Smallest damping (in (mm/rad)² units of JᵀWJ, whose entries are ~1e5 on the LWA 3).
DAMPING_FLOOR = 1e-6
#: Null-space gain towards the seed (redundant chains), per iteration.
NULL_SPACE_GAIN = 0.2
#: Redundant chains: at most this many pose-keeping slides towards the seed once converged.
POLISH_STEPS = 12


class Unreachable(SeqrunError):
    """No configuration inside the joint limits reaches the target."""

    def __init__(self, message: str, position_error_mm: float, angle_error_rad: float,
                 best_deg: np.ndarray) -> None:
        super().__init__(message)
        self.position_error_mm = position_error_mm
        self.angle_error_rad = angle_error_rad
        self.best_deg = best_deg


@dataclass(frozen=True)
class IkSolution:
    """Every joint of the arm (user degrees, locked ones at their value) and the residual."""

    joints_deg: np.ndarray
    position_error_mm: float
    angle_error_rad: float
    iterations: int
    seeds_tried: int


def tool_chain(arm: ArmDescription, tool: str | None = None) -> Chain:
    """The arm's chain whose last frame is the tool centre point (``arm.tool(tool)``).

    Raises :class:`KeyError` for an unknown tool name.
    """
    chain = Chain.from_arm(arm)
    frame = arm.tool(tool)
    if frame is None:
        return chain
    return Chain(base=chain.base, links=chain.links, tool=chain.tool @ frame_matrix(frame))


def target_frame(position_mm: Sequence[float], rpy_deg: Sequence[float]) -> np.ndarray:
    """A 4x4 target from a position (mm) and roll/pitch/yaw (deg, R = Rz Ry Rx)."""
    frame = np.eye(4)
    frame[:3, :3] = matrix_from_rpy(np.radians(np.asarray(rpy_deg, dtype=float)))
    frame[:3, 3] = np.asarray(position_mm, dtype=float)
    return frame


def rotation_vector(rotation: np.ndarray) -> np.ndarray:
    """Axis × angle of a rotation matrix (the log map), exact near 0 and near π."""
    v = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0],
                  rotation[1, 0] - rotation[0, 1]])
    sin2 = math.sqrt(v @ v)  # 2 sin θ
    cos = (rotation[0, 0] + rotation[1, 1] + rotation[2, 2] - 1.0) / 2.0
    angle = math.atan2(sin2 / 2.0, cos)
    if sin2 > 1e-9:
        return v * (angle / sin2)
    if cos > 0:  # θ ≈ 0: first order
        return v / 2.0
    # θ ≈ π: the axis from the diagonal of R = 2aaᵀ - I
    axis = np.sqrt(np.maximum((np.diag(rotation) + 1.0) / 2.0, 0.0))
    k = int(np.argmax(axis))
    for j in range(3):
        if j != k:
            axis[j] = math.copysign(axis[j], rotation[k, j] + rotation[j, k])
    return axis * angle


class IkSolver:
    """Solves for the active joints of ``arm`` with the tool ``tool`` (see module doc).

    ``restarts``: seeds tried after the given one before a target counts as unreachable.
    """

    def __init__(self, arm: ArmDescription, tool: str | None = None, *,
                 position_tolerance_mm: float = POSITION_TOLERANCE_MM,
                 angle_tolerance_rad: float = ANGLE_TOLERANCE_RAD,
                 max_iterations: int = 100, restarts: int = 40) -> None:
        self.arm = arm
        self.chain = tool_chain(arm, tool)
        self.position_tolerance_mm = position_tolerance_mm
        self.angle_tolerance_rad = angle_tolerance_rad
        self.max_iterations = max_iterations
        self.restarts = restarts
        self.active = [i for i, j in enumerate(arm.joints) if j.locked is None]
        self.locked_deg = np.array([j.locked if j.locked is not None else 0.0
                                    for j in arm.joints], dtype=float)
        limits = np.radians([j.limits_deg for j in arm.joints])[self.active]
        self.lower, self.upper = limits[:, 0].copy(), limits[:, 1].copy()
        # a joint whose range is a full turn wraps instead of stopping at its limit
        self.wraps = (self.upper - self.lower) >= 2 * math.pi - 1e-9
        self._weights = np.array([1.0, 1.0, 1.0] + [ORIENTATION_WEIGHT_MM ** 2] * 3)
        self._fold_locked()

    # ---------------------------------------------------------------- geometry
    def _fold_locked(self) -> None:
        """Fixed frames between consecutive active joints, locked joints folded in:
        ``pre[k]`` leads from active joint k-1's frame (after its rotation) to active joint
        k's frame (before its rotation); ``post`` from the last one to the tool."""
        chain, n = self.chain, self.chain.dof
        current = chain.base.copy()
        pre: list[np.ndarray] = []
        for i in range(n):
            if i > 0:
                current = current @ chain.links[i - 1]
            if i in self.active:
                pre.append(current)
                current = np.eye(4)
            else:
                current = current @ _rz(math.radians(self.locked_deg[i]))
        self._pre = pre
        self._post = current @ chain.tool
        self._pre_rows = [tuple(float(x) for x in (*f[:3, :3].ravel(), *f[:3, 3])) for f in pre]

    def forward(self, q_active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Tool frame (4, 4), joint axes (m, 3) and joint origins (m, 3) in the base frame."""
        frame, axes, origins = self._kinematics(q_active)
        return frame, np.array(axes), np.array(origins)

    def _kinematics(self, q_active) -> tuple[np.ndarray, list, list]:
        """:meth:`forward` in plain floats: for a 4x4 chain of six joints numpy's per-call
        overhead costs ten times the arithmetic, and this runs every iteration."""
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
        px = py = pz = 0.0
        axes, origins = [], []
        for (a00, a01, a02, a10, a11, a12, a20, a21, a22, ax, ay, az), angle in zip(
                self._pre_rows, q_active):
            px, py, pz = (px + r00 * ax + r01 * ay + r02 * az, py + r10 * ax + r11 * ay + r12 * az,
                          pz + r20 * ax + r21 * ay + r22 * az)
            r00, r01, r02 = (r00 * a00 + r01 * a10 + r02 * a20, r00 * a01 + r01 * a11 + r02 * a21,
                             r00 * a02 + r01 * a12 + r02 * a22)
            r10, r11, r12 = (r10 * a00 + r11 * a10 + r12 * a20, r10 * a01 + r11 * a11 + r12 * a21,
                             r10 * a02 + r11 * a12 + r12 * a22)
            r20, r21, r22 = (r20 * a00 + r21 * a10 + r22 * a20, r20 * a01 + r21 * a11 + r22 * a21,
                             r20 * a02 + r21 * a12 + r22 * a22)
            axes.append((r02, r12, r22))
            origins.append((px, py, pz))
            c, s = math.cos(angle), math.sin(angle)  # @ Rz(q): columns 0 and 1 only
            r00, r01 = c * r00 + s * r01, c * r01 - s * r00
            r10, r11 = c * r10 + s * r11, c * r11 - s * r10
            r20, r21 = c * r20 + s * r21, c * r21 - s * r20
        frame = np.array([[r00, r01, r02, px], [r10, r11, r12, py], [r20, r21, r22, pz],
                          [0.0, 0.0, 0.0, 1.0]]) @ self._post
        return frame, axes, origins

    def _jacobian(self, frame: np.ndarray, axes: list, origins: list) -> np.ndarray:
        tx, ty, tz = frame[0, 3], frame[1, 3], frame[2, 3]
        columns = []
        for (zx, zy, zz), (ox, oy, oz) in zip(axes, origins):
            dx, dy, dz = tx - ox, ty - oy, tz - oz
            columns.append((zy * dz - zz * dy, zz * dx - zx * dz, zx * dy - zy * dx, zx, zy, zz))
        return np.array(columns).T

    def full_deg(self, q_active: np.ndarray) -> np.ndarray:
        q = self.locked_deg.copy()
        q[self.active] = np.degrees(q_active)
        return q

    def _error(self, frame: np.ndarray, target: np.ndarray) -> np.ndarray:
        e = np.empty(6)
        e[:3] = target[:3, 3] - frame[:3, 3]
        e[3:] = rotation_vector(target[:3, :3] @ frame[:3, :3].T)
        return e

    def _inside(self, q: np.ndarray) -> np.ndarray:
        out = self.wraps & ((q < self.lower) | (q > self.upper))
        q = np.where(out, np.remainder(q - self.lower, 2 * math.pi) + self.lower, q)
        return np.clip(q, self.lower, self.upper)

    def _towards(self, seed: np.ndarray, q: np.ndarray) -> np.ndarray:
        """seed - q, the short way round for joints that turn a full circle."""
        diff = seed - q
        return np.where(self.wraps, np.remainder(diff + math.pi, 2 * math.pi) - math.pi, diff)

    # ---------------------------------------------------------------- solving
    def _converged(self, e: np.ndarray) -> bool:
        return (math.sqrt(e[0] ** 2 + e[1] ** 2 + e[2] ** 2) <= self.position_tolerance_mm
                and math.sqrt(e[3] ** 2 + e[4] ** 2 + e[5] ** 2) <= self.angle_tolerance_rad)

    def _descend(self, target: np.ndarray, q: np.ndarray, seed: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, int, bool]:
        """Levenberg-Marquardt from ``q``; returns (q, error, iterations, converged)."""
        w = self._weights
        m = len(q)
        redundant = m > 6
        identity = np.eye(m)
        frame, axes, origins = self._kinematics(q)
        e = self._error(frame, target)
        cost = 0.5 * float(e @ (w * e))
        boost = 1.0  # grows while steps fail to lower the error (classic LM back-off)
        polish = 0
        for iteration in range(1, self.max_iterations + 1):
            jac = self._jacobian(frame, axes, origins)
            if self._converged(e):
                if not redundant or polish >= POLISH_STEPS:
                    return q, e, iteration - 1, True
                # On the pose: slide along the self-motion towards the seed, so that the
                # swivel ends near it rather than wherever convergence happened to stop.
                pinv = jac.T @ np.linalg.inv(jac @ jac.T + 1e-9 * np.eye(6))
                slide = (identity - pinv @ jac) @ self._towards(seed, q)
                if float(np.max(np.abs(slide))) < 1e-4:
                    return q, e, iteration - 1, True
                polish += 1
                q = self._inside(q + 0.5 * slide)
                frame, axes, origins = self._kinematics(q)
                e = self._error(frame, target)
                cost = 0.5 * float(e @ (w * e))
                continue
            jw = jac.T * w
            step = np.linalg.solve(jw @ jac + (boost * cost + DAMPING_FLOOR) * identity, jw @ e)
            if redundant:
                pinv = jac.T @ np.linalg.inv(jac @ jac.T + 1e-9 * np.eye(6))
                step += (identity - pinv @ jac) @ (NULL_SPACE_GAIN * self._towards(seed, q))
            candidate = self._inside(q + step)
            frame_c, axes_c, origins_c = self._kinematics(candidate)
            e_c = self._error(frame_c, target)
            cost_c = 0.5 * float(e_c @ (w * e_c))
            if cost_c >= cost and not self._converged(e_c):
                # Clamped at a limit or at a fold of the workspace: damp harder, and give
                # this seed up when even tiny steps make no progress.
                boost *= 10.0
                if boost > 1e6:
                    return q, e, iteration, False
                continue
            boost = max(boost / 10.0, 1.0)
            q, frame, axes, origins, e, cost = candidate, frame_c, axes_c, origins_c, e_c, cost_c
        return q, e, self.max_iterations, self._converged(e)

    def _seeds(self, seed: np.ndarray):
        """Further seeds: near the given one first, then anywhere (fixed sequence)."""
        rng = np.random.default_rng(20261123)
        for k in range(self.restarts):
            if k < self.restarts // 4:
                spread = math.radians(15.0 * (k + 1))
                yield self._inside(seed + rng.normal(0.0, spread, seed.shape))
            else:
                yield rng.uniform(self.lower, self.upper)

    def solve(self, target: np.ndarray, seed_deg: npt.ArrayLike) -> IkSolution:
        """Joints that put the tool at ``target`` (4x4, mm), starting from ``seed_deg``
        (every joint of the arm, user degrees). Raises :class:`Unreachable`."""
        target = np.asarray(target, dtype=float)
        if target.shape != (4, 4) or not np.all(np.isfinite(target)):
            raise ValueError("the target must be a finite 4x4 frame")
        seed_full = np.asarray(seed_deg, dtype=float)
        if seed_full.shape != (self.arm.dof,) or not np.all(np.isfinite(seed_full)):
            raise ValueError(f"the seed must be {self.arm.dof} finite joint angles")
        seed = self._inside(np.radians(seed_full[self.active]))
        best: tuple[float, np.ndarray, np.ndarray] | None = None
        iterations = 0
        starts = [seed]
        generator = self._seeds(seed)
        tried = 0
        start: np.ndarray | None
        while True:
            if tried < len(starts):
                start = starts[tried]
            else:
                start = next(generator, None)
                if start is None:
                    break
            tried += 1
            # The swivel is pulled towards the seed from the seed and its neighbours; from a
            # far restart that pull would fight convergence, so it holds its own start.
            anchor = seed if tried <= 1 + self.restarts // 4 else start
            q, e, used, ok = self._descend(target, start, anchor)
            iterations += used
            if ok:
                return IkSolution(self.full_deg(q), float(np.linalg.norm(e[:3])),
                                  float(np.linalg.norm(e[3:])), iterations, tried)
            score = float(np.linalg.norm(e[:3]) + ORIENTATION_WEIGHT_MM * np.linalg.norm(e[3:]))
            if best is None or score < best[0]:
                best = (score, q, e)
        assert best is not None
        _, q, e = best
        dist, angle = float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:]))
        raise Unreachable(
            f"unreachable: no configuration inside the joint limits reaches the target "
            f"(closest found: {dist:.3f} mm and {math.degrees(angle):.4f}° away, after "
            f"{tried} seeds)", dist, angle, self.full_deg(q))


def _rz(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0, 0.0], [s, c, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0],
                     [0.0, 0.0, 0.0, 1.0]])
