"""Distances between the arm's links and the facility (pure numpy, no I/O).

The links are capsules (a segment between two frame origins of the chain, and a radius);
the facility's obstacles are planes (half-spaces), boxes and finite cylinders, all in the
base frame; self-collision is checked between links that are not neighbours in the
chain. The tools' volumes (:mod:`seqrun.arm.tools`) are capsules too, carried by the
end-effector frame, checked against the obstacles and every link they are not bolted to. Everything is vectorised over configurations: ``(..., dof)`` joint angles in,
``(...)`` distances out, one Python loop over the (few) capsules and obstacles only.

Distances are *clearances*: surface to surface, in mm, negative when they overlap. A
capsule's distance to an obstacle is the smallest distance of its segment to it minus its
radius: exact for planes, boxes (closed form) and link pairs, a lower bound within µm for
cylinders (golden-section search on the convex distance along the segment); far from a
box or cylinder (beyond :data:`EXACT_WITHIN_MM` of the margin) a cheap lower bound from
its bounding sphere. A reported clearance is never more than the true one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from seqrun.arm.description import ArmDescription, Obstacle
from seqrun.arm.kinematics import Chain, frame_origins, matrix_from_rpy
from seqrun.arm.tools import ToolVolumes

__all__ = ["EXACT_WITHIN_MM", "Clearance", "Geometry"]

_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
#: Beyond the margin and the capsule radius, how far from an obstacle's bounding sphere
#: exact distances are still computed (further out a lower bound is reported), mm.
EXACT_WITHIN_MM = 100.0
#: Golden-section steps along a segment: the bracket shrinks to 0.618^20 ≈ 7e-5 of it
#: (0.03 mm on a 400 mm link), subtracted from the result (a conservative clearance).
_SEARCH_STEPS = 20


@dataclass(frozen=True)
class Clearance:
    """The smallest clearance of one configuration and which pair it is."""

    distance_mm: float
    pair: str          # "forearm~desk", "column~wrist"
    index: int         # sample index where it occurs (for a batch)


def point_box(points: np.ndarray, center: np.ndarray, rotation: np.ndarray,
              half: np.ndarray) -> np.ndarray:
    """Distance of points ``(..., 3)`` to a box of half sizes ``half`` (negative inside)."""
    local = (points - center) @ rotation  # into the box frame
    outside = np.maximum(np.abs(local) - half, 0.0)
    inside = np.minimum(np.max(np.abs(local) - half, axis=-1), 0.0)
    return np.linalg.norm(outside, axis=-1) + inside


def segment_box(a: np.ndarray, b: np.ndarray, center: np.ndarray, rotation: np.ndarray,
                half: np.ndarray) -> np.ndarray:
    """Exact distance of segments ab ``(..., 3)`` to a box (negative inside), without
    iterating: along the segment the squared outside distance is a piecewise quadratic
    whose pieces end where a coordinate crosses a face plane; its minimum is at a piece's
    end or at the vertex of a piece's quadratic, and those few candidates are evaluated."""
    local_a = (a - center) @ rotation
    local_d = (b - a) @ rotation
    safe = np.where(np.abs(local_d) > 1e-12, local_d, 1.0)
    crossings = np.concatenate([(half - local_a) / safe, (-half - local_a) / safe], axis=-1)
    crossings = np.where(np.abs(np.concatenate([local_d, local_d], axis=-1)) > 1e-12,
                         crossings, 0.0)
    ends = np.sort(np.concatenate([np.zeros(a.shape[:-1] + (1,)), np.clip(crossings, 0, 1),
                                   np.ones(a.shape[:-1] + (1,))], axis=-1), axis=-1)  # (..., 8)
    middle = (ends[..., :-1] + ends[..., 1:]) / 2  # (..., 7)
    x_mid = local_a[..., None, :] + middle[..., None] * local_d[..., None, :]  # (..., 7, 3)
    side = np.where(x_mid > half, 1.0, np.where(x_mid < -half, -1.0, 0.0))
    offset = local_a[..., None, :] - side * half  # per outside coordinate: x - side*h
    active = side != 0
    d = np.where(active, local_d[..., None, :], 0.0)
    num = -np.sum(np.where(active, offset, 0.0) * d, axis=-1)
    den = np.sum(d * d, axis=-1)
    vertex = np.clip(np.where(den > 1e-12, num / np.where(den > 1e-12, den, 1.0), middle),
                     ends[..., :-1], ends[..., 1:])
    candidates = np.concatenate([ends, vertex], axis=-1)  # (..., 15)
    points = local_a[..., None, :] + candidates[..., None] * local_d[..., None, :]
    outside = np.linalg.norm(np.maximum(np.abs(points) - half, 0.0), axis=-1)
    inside = np.minimum(np.max(np.abs(points) - half, axis=-1), 0.0)
    return np.min(outside + inside, axis=-1)


def point_cylinder(points: np.ndarray, base: np.ndarray, axis: np.ndarray, radius: float,
                   height: float) -> np.ndarray:
    """Distance of points ``(..., 3)`` to a solid cylinder standing on ``base`` along the
    unit ``axis`` (negative inside)."""
    rel = points - base
    along = rel @ axis
    radial = np.linalg.norm(rel - along[..., None] * axis, axis=-1)
    d_r = radial - radius
    d_a = np.maximum(-along, along - height)
    outside = np.hypot(np.maximum(d_r, 0.0), np.maximum(d_a, 0.0))
    return outside + np.minimum(np.maximum(d_r, d_a), 0.0)


def segment_min(a: np.ndarray, b: np.ndarray, distance) -> np.ndarray:
    """A lower bound, within a few µm, of min over t in [0, 1] of distance(a + t (b - a))
    for a convex, 1-Lipschitz ``distance`` (to a convex set): golden-section search, then
    the bracket's width times the segment length is subtracted, so the result never
    overstates the clearance."""
    lo = np.zeros(a.shape[:-1])
    hi = np.ones(a.shape[:-1])
    ab = b - a
    length = np.linalg.norm(ab, axis=-1)
    x1 = hi - _GOLDEN * (hi - lo)
    x2 = lo + _GOLDEN * (hi - lo)
    f1 = distance(a + x1[..., None] * ab)
    f2 = distance(a + x2[..., None] * ab)
    for _ in range(_SEARCH_STEPS):
        left = f1 < f2  # the minimum lies in [lo, x2]
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
        x2n = np.where(left, x1, lo + _GOLDEN * (hi - lo))
        x1n = np.where(left, hi - _GOLDEN * (hi - lo), x2)
        f_new = distance(a + np.where(left, x1n, x2n)[..., None] * ab)
        f1, f2 = np.where(left, f_new, f2), np.where(left, f1, f_new)
        x1, x2 = x1n, x2n
    ends = np.minimum(distance(a), distance(b))
    return np.minimum(np.minimum(f1, f2) - (hi - lo) * length, ends)


def _segment_point(a: np.ndarray, b: np.ndarray, point: np.ndarray) -> np.ndarray:
    ab = b - a
    denom = np.einsum("...i,...i", ab, ab)
    t = np.clip(np.einsum("...i,...i", point - a, ab) / np.where(denom > 1e-12, denom, 1.0), 0, 1)
    return np.linalg.norm(a + t[..., None] * ab - point, axis=-1)


def _segment_distance(p1, q1, p2, q2) -> float:
    """:func:`segment_segment` for one pair of segments given as float triples."""
    p1x, p1y, p1z = p1
    p2x, p2y, p2z = p2
    d1x, d1y, d1z = q1[0] - p1x, q1[1] - p1y, q1[2] - p1z
    d2x, d2y, d2z = q2[0] - p2x, q2[1] - p2y, q2[2] - p2z
    rx, ry, rz = p1x - p2x, p1y - p2y, p1z - p2z
    a = d1x * d1x + d1y * d1y + d1z * d1z
    e = d2x * d2x + d2y * d2y + d2z * d2z
    f = d2x * rx + d2y * ry + d2z * rz
    if a == 0.0 and e == 0.0:
        s = t = 0.0
    elif a == 0.0:
        s, t = 0.0, min(max(f / e, 0.0), 1.0)
    else:
        c = d1x * rx + d1y * ry + d1z * rz
        if e == 0.0:
            s, t = min(max(-c / a, 0.0), 1.0), 0.0
        else:
            b = d1x * d2x + d1y * d2y + d1z * d2z
            # a e - b b and b f - c e through n = d1 x d2 (see segment_segment)
            nx, ny, nz = d1y * d2z - d1z * d2y, d1z * d2x - d1x * d2z, d1x * d2y - d1y * d2x
            denom = nx * nx + ny * ny + nz * nz
            if denom > _PARALLEL * a * e:
                s = ((ny * d2z - nz * d2y) * rx + (nz * d2x - nx * d2z) * ry
                     + (nx * d2y - ny * d2x) * rz) / denom
                s = min(max(s, 0.0), 1.0)
            else:
                s = 0.0
            t = (b * s + f) / e
            if t < 0.0:
                s, t = min(max(-c / a, 0.0), 1.0), 0.0
            elif t > 1.0:
                s, t = min(max((b - c) / a, 0.0), 1.0), 1.0
    x = p1x + s * d1x - p2x - t * d2x
    y = p1y + s * d1y - p2y - t * d2y
    z = p1z + s * d1z - p2z - t * d2z
    return math.sqrt(x * x + y * y + z * z)


#: Segments count as parallel when the sine squared of their angle is below this. The
#: test is relative (an absolute one took a short segment for a parallel one and measured
#: from its first point only), and the closest point of skew lines comes from n = d1 x d2
#: (|n|^2 = a e - b^2, (n x d2).r = b f - c e without their cancellation): its error in
#: the distance stays at rounding level however small the angle, so only truly parallel
#: segments (where any start works) take s = 0.
_PARALLEL = 1e-24


def segment_segment(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray
                    ) -> np.ndarray:
    """Closest distance between segments p1q1 and p2q2 (batched; Ericson 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.einsum("...i,...i", d1, d1)
    e = np.einsum("...i,...i", d2, d2)
    f = np.einsum("...i,...i", d2, r)
    c = np.einsum("...i,...i", d1, r)
    b = np.einsum("...i,...i", d1, d2)
    n = np.cross(d1, d2)
    denom = np.einsum("...i,...i", n, n)  # a e - b^2, without its cancellation
    safe_a = np.where(a > 0.0, a, 1.0)
    safe_e = np.where(e > 0.0, e, 1.0)
    # general case: closest points of the lines, s clamped, t from s, then s again;
    # parallel segments (see _PARALLEL): s = 0, then t and s clamped
    skew = denom > _PARALLEL * a * e
    numerator = np.einsum("...i,...i", np.cross(n, d2), r)  # b f - c e
    s = np.where(skew, np.clip(numerator / np.where(skew, denom, 1.0), 0.0, 1.0), 0.0)
    t = (b * s + f) / safe_e
    s = np.where(t < 0, np.clip(-c / safe_a, 0, 1),
                 np.where(t > 1, np.clip((b - c) / safe_a, 0, 1), s))
    t = np.clip(t, 0.0, 1.0)
    # degenerate segments (points)
    first_point, second_point = a == 0.0, e == 0.0
    s = np.where(second_point, np.clip(-c / safe_a, 0, 1), s)
    t = np.where(second_point, 0.0, t)
    t = np.where(first_point, np.clip(f / safe_e, 0, 1), t)
    s = np.where(first_point, 0.0, s)
    c1 = p1 + s[..., None] * d1
    c2 = p2 + t[..., None] * d2
    return np.linalg.norm(c1 - c2, axis=-1)


class Geometry:
    """Link capsules and obstacles of an arm description (``arm.geometry``)."""

    def __init__(self, arm: ArmDescription) -> None:
        spec = arm.geometry
        self.arm = arm
        self.chain = Chain.from_arm(arm)
        self.margin_mm = spec.margin_mm
        names = ["base"] + [j.name for j in arm.joints] + ["end_effector"]
        self._frame = {name: i for i, name in enumerate(names)}
        self.capsules = list(spec.capsules)
        self.capsule_names = [c.name for c in self.capsules]
        # the tools' volumes follow the links' (seqrun/arm/tools.py): their ends are points
        # of the end-effector frame, appended after the chain's frame origins
        self.tools = ToolVolumes(arm)
        parts = self.tools.parts
        links = len(self.capsules)
        ends = [[self._frame[c.start], self._frame[c.end]] for c in self.capsules]
        ends += [[len(names) + 2 * k, len(names) + 2 * k + 1] for k in range(len(parts))]
        self._ends = np.array(ends, dtype=int).reshape(-1, 2)
        self._radii = np.array([c.radius_mm for c in self.capsules]
                               + [part.radius_mm for part in parts], dtype=float)
        self._max_radius = float(self._radii.max()) if len(self._radii) else 0.0
        volume_names = self.capsule_names + [part.label for part in parts]
        # self-collision: links that are not neighbours in the list (chain order)
        self.pairs = [(i, j) for i in range(links) for j in range(i + 2, links)
                      if (self.capsules[i].name, self.capsules[j].name) not in spec.allowed_pairs
                      and (self.capsules[j].name, self.capsules[i].name) not in spec.allowed_pairs]
        # a tool against every link but those it is bolted to (touching the flange or the
        # end-effector); a tool's parts and different tools are one rigid body
        flange = {arm.joints[-1].name, "end_effector"}
        allowed = {frozenset(pair) for pair in spec.allowed_pairs}
        for t, part in enumerate(parts):
            for i, capsule in enumerate(self.capsules):
                if capsule.start in flange or capsule.end in flange:
                    continue
                if any(frozenset((capsule.name, name)) in allowed for name in part.names()):
                    continue
                self.pairs.append((i, links + t))
        self.obstacles = list(spec.obstacles)
        # what is evaluated, in column order: obstacles (their capsules), then link pairs
        self._checked: list[tuple[Obstacle, np.ndarray]] = []
        self._names: list[str] = []
        for obstacle in self.obstacles:
            ignored = set(obstacle.ignore_links)
            checked = [k for k, c in enumerate(self.capsules) if c.name not in ignored]
            checked += [links + t for t, part in enumerate(parts) if not part.names() & ignored]
            if checked:
                self._checked.append((obstacle, np.array(checked, dtype=int)))
                self._names += [f"{volume_names[k]}~{obstacle.name}" for k in checked]
        self._pair_index = (np.array([i for i, _ in self.pairs], dtype=int),
                            np.array([j for _, j in self.pairs], dtype=int))
        self._names += [f"{volume_names[i]}~{volume_names[j]}" for i, j in self.pairs]
        # plain-float copies for the single-configuration path
        self._radii_list = self._radii.tolist()
        frames = [self.chain.base, *self.chain.links]
        self._rows = [tuple(float(x) for x in (*f[:3, :3].ravel(), *f[:3, 3])) for f in frames]
        # the end-effector's origin and the tools' points in the last joint's frame
        flange_points = np.concatenate([np.zeros((1, 3)), self.tools.points_mm])
        flange_points = flange_points @ self.chain.tool[:3, :3].T + self.chain.tool[:3, 3]
        self._flange_points = [tuple(float(x) for x in p) for p in flange_points]
        self._planes_only = all(o.kind == "plane" for o in self.obstacles)
        self._planes = {}
        for o in self.obstacles:
            if o.kind == "plane" and o.plane is not None:  # (a plane obstacle has one)
                n = np.asarray(o.plane.normal, dtype=float)
                n = n / np.linalg.norm(n)
                self._planes[o.name] = (*n.tolist(), float(n @ np.asarray(o.plane.point_mm)))
        # the single-configuration path's columns, in column order: (capsule ends, plane,
        # radius, name) per obstacle column, (both capsules' ends and radii, name) per pair
        ends = self._ends.tolist()
        names_iter = iter(self._names)
        self._plane_columns = [
            (*ends[k], *self._planes[obstacle.name], self._radii_list[k], next(names_iter))
            for obstacle, checked in self._checked if obstacle.kind == "plane"
            for k in checked.tolist()] if self._planes_only else []
        self._pair_columns = [
            (*ends[i], *ends[j], self._radii_list[i], self._radii_list[j], next(names_iter))
            for i, j in self.pairs] if self._planes_only else []

    @property
    def empty(self) -> bool:
        return not len(self._radii)

    @property
    def radii_mm(self) -> np.ndarray:
        """The volumes' radii, in :meth:`endpoints` order (links, then tools)."""
        return self._radii

    @property
    def volume_names(self) -> list[str]:
        """The volumes' names, in :meth:`endpoints` order (links, then tools)."""
        return self.capsule_names + [part.label for part in self.tools.parts]

    @property
    def ee_points(self) -> np.ndarray | None:
        """The points of the end-effector frame the volumes need (the tools'), for
        :func:`~seqrun.arm.kinematics.frame_origins`; None without tools."""
        return None if self.tools.empty else self.tools.points_mm

    def endpoints(self, q_rad: np.ndarray, origins: np.ndarray | None = None) -> np.ndarray:
        """Capsule segments ``(..., capsules, 2, 3)`` at joint angles (rad), the links' then
        the tools'; ``origins``: their :func:`~seqrun.arm.kinematics.frame_origins` with
        :attr:`ee_points` when the caller has them."""
        expected = self.chain.dof + 1 + len(self.tools.points_mm)
        if origins is None or origins.shape[-2] != expected:
            origins = frame_origins(self.chain, q_rad, self.ee_points)  # (..., n+1+2m, 3)
        origin = np.zeros(origins.shape[:-2] + (1, 3))
        points = np.concatenate([origin, origins], axis=-2)  # "base" = the mount, index 0
        return points[..., self._ends, :]

    def clearances(self, q_rad: np.ndarray, origins: np.ndarray | None = None
                   ) -> tuple[np.ndarray, list[str]]:
        """Every pair's clearance (mm): ``(..., pairs)`` and the pair names (one numpy
        evaluation per obstacle over all its capsules, one for all self-collision pairs).
        ``origins``: as for :meth:`endpoints`."""
        q = np.asarray(q_rad, dtype=float)
        if not self._names:
            return np.full(q.shape[:-1] + (0,), np.inf), []
        seg = self.endpoints(q, origins)
        columns: list[np.ndarray] = []
        for obstacle, links in self._checked:
            a, b = seg[..., links, 0, :], seg[..., links, 1, :]
            columns.append(self._obstacle_distance(obstacle, a, b) - self._radii[links])
        if self.pairs:
            i, j = self._pair_index
            d = segment_segment(seg[..., i, 0, :], seg[..., i, 1, :],
                                 seg[..., j, 0, :], seg[..., j, 1, :])
            columns.append(d - self._radii[i] - self._radii[j])
        return np.concatenate(columns, axis=-1), self._names

    def _obstacle_distance(self, obstacle, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Distance (mm) of segments ab ``(..., 3)`` to an obstacle's surface.

        Boxes and cylinders are first bounded by a sphere: where the segment is more than
        :data:`EXACT_WITHIN_MM` beyond the margin from it, that lower bound is the answer
        (cheap, and never more than the true distance); the exact distance is computed
        only for the segments closer than that."""
        shape = obstacle.shape
        if obstacle.kind == "plane":
            normal = np.asarray(shape.normal, dtype=float)
            normal = normal / np.linalg.norm(normal)
            point = np.asarray(shape.point_mm, dtype=float)
            return np.minimum((a - point) @ normal, (b - point) @ normal)
        if obstacle.kind == "box":
            center = np.asarray(shape.center_mm, dtype=float)
            rotation = matrix_from_rpy(np.radians(shape.rpy_deg))
            half = np.asarray(shape.size_mm, dtype=float) / 2.0
            sphere = (center, float(np.linalg.norm(half)))
            exact = lambda a, b: segment_box(a, b, center, rotation, half)  # noqa: E731
        else:
            base = np.asarray(shape.base_mm, dtype=float)
            axis = np.asarray(shape.axis, dtype=float)
            axis = axis / np.linalg.norm(axis)
            sphere = (base + axis * shape.height_mm / 2,
                      math.hypot(shape.radius_mm, shape.height_mm / 2))

            def exact(a, b):
                return segment_min(a, b, lambda p: point_cylinder(
                    p, base, axis, shape.radius_mm, shape.height_mm))
        bound = _segment_point(a, b, sphere[0]) - sphere[1]
        near = bound < self.margin_mm + self._max_radius + EXACT_WITHIN_MM
        if np.any(near):
            bound = bound.copy()
            bound[near] = exact(a[near], b[near])
        return bound

    def _origins(self, q) -> list[tuple[float, float, float]]:
        """Frame origins (mount, joints 1..n, end-effector, the tools' points) of one
        configuration, in plain floats: the run-time check does this every control cycle."""
        rows = self._rows
        (r00, r01, r02, r10, r11, r12, r20, r21, r22, px, py, pz) = rows[0]
        points = [(0.0, 0.0, 0.0), (px, py, pz)]
        c, s = math.cos(q[0]), math.sin(q[0])
        r00, r01 = c * r00 + s * r01, c * r01 - s * r00
        r10, r11 = c * r10 + s * r11, c * r11 - s * r10
        r20, r21 = c * r20 + s * r21, c * r21 - s * r20
        for (a00, a01, a02, a10, a11, a12, a20, a21, a22, ax, ay, az), angle in zip(
                rows[1:], q[1:]):
            px, py, pz = (px + r00 * ax + r01 * ay + r02 * az,
                          py + r10 * ax + r11 * ay + r12 * az,
                          pz + r20 * ax + r21 * ay + r22 * az)
            r00, r01, r02 = (r00 * a00 + r01 * a10 + r02 * a20,
                             r00 * a01 + r01 * a11 + r02 * a21,
                             r00 * a02 + r01 * a12 + r02 * a22)
            r10, r11, r12 = (r10 * a00 + r11 * a10 + r12 * a20,
                             r10 * a01 + r11 * a11 + r12 * a21,
                             r10 * a02 + r11 * a12 + r12 * a22)
            r20, r21, r22 = (r20 * a00 + r21 * a10 + r22 * a20,
                             r20 * a01 + r21 * a11 + r22 * a21,
                             r20 * a02 + r21 * a12 + r22 * a22)
            points.append((px, py, pz))
            c, s = math.cos(angle), math.sin(angle)
            r00, r01 = c * r00 + s * r01, c * r01 - s * r00
            r10, r11 = c * r10 + s * r11, c * r11 - s * r10
            r20, r21 = c * r20 + s * r21, c * r21 - s * r20
        for ax, ay, az in self._flange_points:  # the end-effector, then the tools' points
            points.append((px + r00 * ax + r01 * ay + r02 * az,
                           py + r10 * ax + r11 * ay + r12 * az,
                           pz + r20 * ax + r21 * ay + r22 * az))
        return points

    def _smallest_one(self, q) -> Clearance:
        """:meth:`smallest` of one configuration when every obstacle is a plane."""
        points = self._origins(q)
        best, best_name = math.inf, ""
        for start, end, nx, ny, nz, offset, radius, name in self._plane_columns:
            ax, ay, az = points[start]
            bx, by, bz = points[end]
            d = min(ax * nx + ay * ny + az * nz, bx * nx + by * ny + bz * nz) - offset
            d -= radius
            if d < best:
                best, best_name = d, name
        for start_i, end_i, start_j, end_j, radius_i, radius_j, name in self._pair_columns:
            d = (_segment_distance(points[start_i], points[end_i], points[start_j], points[end_j])
                 - radius_i - radius_j)
            if d < best:
                best, best_name = d, name
        return Clearance(best, best_name, 0)

    def within(self, q_rad: np.ndarray, origins: np.ndarray | None, margin_mm: float
               ) -> tuple[Clearance | None, list[Clearance]]:
        """Over a batch ``(k, dof)`` (``origins``: as for :meth:`endpoints`): the smallest
        clearance, and every pair that comes within ``margin_mm``, each at the sample where
        it is closest, in sample order (a move's collisions as they happen, not only the
        worst one)."""
        q = np.asarray(q_rad, dtype=float)
        if not self._names:
            return None, []
        values, names = self.clearances(q, origins)
        if not names or not values.size:
            return None, []
        values = values.reshape(-1, len(names))
        at = np.argmin(values, axis=0)  # per pair: the sample where it is closest
        closest = values[at, np.arange(len(names))]
        worst = int(np.argmin(closest))
        smallest = Clearance(float(closest[worst]), names[worst], int(at[worst]))
        close = [Clearance(float(closest[k]), names[k], int(at[k]))
                 for k in np.flatnonzero(closest < margin_mm)]
        return smallest, sorted(close, key=lambda c: (c.index, c.distance_mm))

    def smallest(self, q_rad: np.ndarray, origins: np.ndarray | None = None
                 ) -> Clearance | None:
        """The smallest clearance over a batch ``(k, dof)`` (or one configuration);
        ``origins`` of a batch: as for :meth:`endpoints`."""
        q = np.asarray(q_rad, dtype=float)
        if not self._names:
            return None
        if q.ndim == 1 and self._planes_only:
            return self._smallest_one(q.tolist())
        if q.ndim == 1:
            q, origins = q[None], None if origins is None else origins[None]
        values, names = self.clearances(q, origins)
        if not names:
            return None
        flat = int(np.argmin(values))
        index, pair = divmod(flat, values.shape[-1])
        return Clearance(float(values.reshape(-1)[flat]), names[pair], index)

