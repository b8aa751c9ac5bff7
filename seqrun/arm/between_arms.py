"""Clearance between two arms' volumes in a common facility frame (pure numpy, no I/O).

Each arm's links and tools are capsules (:class:`seqrun.arm.geometry.Geometry`) in its own
base frame; its base pose in the facility frame (``[arms.ID] base`` of ``seqrun.toml``)
carries them into the common frame, where every capsule of one arm is checked against
every capsule of the other. Clearances are surface to surface, mm, negative when the
volumes overlap, like the guard clearances of one arm.

Where two moments of the arms cannot be put on one time line (an operator's answer comes
when it comes), an arm's path is taken in stretches (:func:`swept`): each stretch is its
capsules at one configuration, every capsule grown by the farthest any of its points moves
within the stretch (a rigid link's point between its two ends moves no farther than the
farther end), so the grown capsules hold every configuration of the stretch; every pair of
stretches that can meet is then checked (:func:`swept_clearance`). While the arms move,
:func:`stopping_travel_mm` bounds how far any point of an arm can still go before it
stands (ISO/TS 15066 speed and separation): each joint's reaction travel and braking
distance times the longest lever it turns.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from seqrun.arm.geometry import Clearance, Geometry, segment_segment
from seqrun.arm.kinematics import frame_origins, matrix_from_rpy

__all__ = ["Swept", "base_transform", "base_of", "between_arms", "levers_mm",
           "pair_clearance", "sphere_gap", "stopping_travel_mm", "swept", "swept_clearance",
           "volumes_in_facility"]


def base_transform(position_mm: Sequence[float], rpy_deg: Sequence[float]) -> np.ndarray:
    """4x4: a base frame at ``position_mm``, turned by roll/pitch/yaw ``rpy_deg`` (fixed
    axes x, y, z), in the facility frame."""
    frame = np.eye(4)
    frame[:3, :3] = matrix_from_rpy(np.radians(np.asarray(rpy_deg, dtype=float)))
    frame[:3, 3] = np.asarray(position_mm, dtype=float)
    return frame


def base_of(base) -> np.ndarray:
    """4x4 of a base pose given as ``position_mm`` and ``rpy_deg`` attributes
    (``[arms.ID] base``); None is the facility frame itself."""
    if base is None:
        return np.eye(4)
    return base_transform(base.position_mm, base.rpy_deg)


def volumes_in_facility(geometry: Geometry, base: np.ndarray, q_rad: np.ndarray
                        ) -> np.ndarray:
    """The capsule segments ``(k, capsules, 2, 3)`` of configurations ``(k, dof)`` (rad)
    in the facility frame."""
    seg = geometry.endpoints(np.asarray(q_rad, dtype=float))
    return seg @ base[:3, :3].T + base[:3, 3]


def _distances(first: tuple[str, Geometry, np.ndarray], second: tuple[str, Geometry,
               np.ndarray], q_first: np.ndarray, q_second: np.ndarray) -> np.ndarray | None:
    """Every volume of one arm against every volume of the other: ``(k, na, nb)`` mm."""
    (_, geo_a, base_a), (_, geo_b, base_b) = first, second
    qa, qb = np.atleast_2d(q_first), np.atleast_2d(q_second)
    if geo_a.empty or geo_b.empty or not len(qa):
        return None
    if len(qa) != len(qb):
        raise ValueError("the two arms need the same number of samples")
    seg_a = volumes_in_facility(geo_a, base_a, qa)  # (k, na, 2, 3)
    seg_b = volumes_in_facility(geo_b, base_b, qb)  # (k, nb, 2, 3)
    d = segment_segment(seg_a[:, :, None, 0, :], seg_a[:, :, None, 1, :],
                        seg_b[:, None, :, 0, :], seg_b[:, None, :, 1, :])
    return d - geo_a.radii_mm[None, :, None] - geo_b.radii_mm[None, None, :]


def _at(first, second, d: np.ndarray, index: int) -> Clearance:
    row = d[index]
    i, j = np.unravel_index(int(np.argmin(row)), row.shape)
    names_a, names_b = first[1].volume_names, second[1].volume_names
    return Clearance(float(row[i, j]), f"{first[0]}.{names_a[i]}~{second[0]}.{names_b[j]}",
                     index)


def between_arms(first: tuple[str, Geometry, np.ndarray], second: tuple[str, Geometry,
                 np.ndarray], q_first: np.ndarray, q_second: np.ndarray,
                 below_mm: float | None = None) -> tuple[Clearance, Clearance | None] | None:
    """The smallest clearance between two arms over time-aligned samples: ``first`` and
    ``second`` are (arm id, geometry, base transform), ``q_first[k]`` and ``q_second[k]``
    the two arms' joints (rad) at the same instant. Returns ``(smallest, first sample
    below below_mm or None)``; a pair reads ``"A.forearm~B.wrist"``, ``index`` is the
    sample. None: an arm has no volumes."""
    d = _distances(first, second, q_first, q_second)
    if d is None:
        return None
    per_sample = d.reshape(len(d), -1).min(axis=1)
    smallest = _at(first, second, d, int(np.argmin(per_sample)))
    early = None
    if below_mm is not None:
        below = np.flatnonzero(per_sample < below_mm)
        if len(below):
            early = _at(first, second, d, int(below[0]))
    return smallest, early


# --------------------------------------------------------------------- swept stretches
@dataclass(frozen=True)
class Swept:
    """An arm's volumes over stretches of its path: per stretch ``k`` the capsule segments
    ``(k, capsules, 2, 3)`` (facility frame) at one configuration, each grown by
    ``grow_mm[k, capsule]``, holding the arm from ``start_s[k]`` to ``end_s[k]`` (the
    path's own time)."""

    segments: np.ndarray
    grow_mm: np.ndarray
    start_s: np.ndarray
    end_s: np.ndarray

    def __len__(self) -> int:
        return len(self.start_s)


def swept(geometry: Geometry, base: np.ndarray, times: np.ndarray, q_rad: np.ndarray,
          per: int = 10, until_s: float | None = None) -> Swept:
    """``q_rad[k]`` at ``times[k]`` in stretches of ``per`` samples (each shares its last
    sample with the next, so nothing between two samples is left out). One sample is one
    stretch held until ``until_s`` (a rest; ``inf`` allowed)."""
    q = np.atleast_2d(np.asarray(q_rad, dtype=float))
    times = np.atleast_1d(np.asarray(times, dtype=float))
    seg = volumes_in_facility(geometry, base, q)  # (n, caps, 2, 3)
    if len(q) == 1:
        end = times[0] if until_s is None else until_s
        return Swept(seg, np.zeros(seg.shape[:2]), times[:1], np.array([end], dtype=float))
    firsts = list(range(0, len(q) - 1, per))
    middles, grows, starts, ends = [], [], [], []
    for first in firsts:
        last = min(first + per, len(q) - 1)
        mid = (first + last) // 2
        # the farther end of each capsule, from its place at the middle sample
        moved = np.linalg.norm(seg[first:last + 1] - seg[mid], axis=-1).max(axis=(0, 2))
        middles.append(mid)
        grows.append(moved)
        starts.append(times[first])
        ends.append(times[last])
    return Swept(seg[middles], np.array(grows), np.array(starts), np.array(ends))


def pair_clearance(seg_a: np.ndarray, radii_a: np.ndarray, seg_b: np.ndarray,
                   radii_b: np.ndarray) -> np.ndarray:
    """Every capsule of ``seg_a (..., na, 2, 3)`` against every one of ``seg_b (..., nb,
    2, 3)``, surface to surface: ``(..., na, nb)`` mm; ``radii_*`` broadcast like the
    segments without their last two axes (grown radii)."""
    d = segment_segment(seg_a[..., :, None, 0, :], seg_a[..., :, None, 1, :],
                        seg_b[..., None, :, 0, :], seg_b[..., None, :, 1, :])
    return d - radii_a[..., :, None] - radii_b[..., None, :]


def sphere_gap(seg_a: np.ndarray, radii_a: np.ndarray, seg_b: np.ndarray,
               radii_b: np.ndarray) -> np.ndarray:
    """A cheap lower bound of :func:`pair_clearance` (one configuration each): every
    capsule's bounding sphere (its middle, half its length plus its radius)."""
    mid_a, mid_b = seg_a.mean(axis=-2), seg_b.mean(axis=-2)
    half_a = np.linalg.norm(seg_a[..., 1, :] - seg_a[..., 0, :], axis=-1) / 2 + radii_a
    half_b = np.linalg.norm(seg_b[..., 1, :] - seg_b[..., 0, :], axis=-1) / 2 + radii_b
    apart = np.linalg.norm(mid_a[:, None, :] - mid_b[None, :, :], axis=-1)
    return apart - half_a[:, None] - half_b[None, :]


def swept_clearance(first: tuple[str, Geometry, Swept], second: tuple[str, Geometry, Swept],
                    can_meet: np.ndarray, block: int = 64
                    ) -> tuple[float, str, int, int] | None:
    """The smallest clearance between stretches of two arms that ``can_meet[i, j]``
    (stretch i of the first, j of the second): ``(mm, "A.forearm~B.wrist", i, j)``;
    None when no pair can meet."""
    (name_a, geo_a, sw_a), (name_b, geo_b, sw_b) = first, second
    if geo_a.empty or geo_b.empty or not can_meet.any():
        return None
    best: tuple[float, str, int, int] | None = None
    rows = np.flatnonzero(can_meet.any(axis=1))
    for at in range(0, len(rows), block):
        ia = rows[at:at + block]
        ja = np.flatnonzero(can_meet[ia].any(axis=0))
        ra = geo_a.radii_mm[None, :] + sw_a.grow_mm[ia]  # (ia, na)
        rb = geo_b.radii_mm[None, :] + sw_b.grow_mm[ja]  # (ja, nb)
        d = pair_clearance(sw_a.segments[ia][:, None], ra[:, None],
                           sw_b.segments[ja][None, :], rb[None, :])  # (ia, ja, na, nb)
        d = np.where(can_meet[np.ix_(ia, ja)][..., None, None], d, np.inf)
        flat = int(np.argmin(d))
        i, j, ca, cb = np.unravel_index(flat, d.shape)
        value = float(d[i, j, ca, cb])
        if best is None or value < best[0]:
            best = (value, f"{name_a}.{geo_a.volume_names[ca]}~{name_b}."
                           f"{geo_b.volume_names[cb]}", int(ia[i]), int(ja[j]))
    return best


# --------------------------------------------------------------------- stopping travel
def levers_mm(geometry: Geometry) -> np.ndarray:
    """For each joint, the longest distance from its axis to any point of the volumes it
    turns, in any configuration: the chain's lengths from the joint's frame origin on
    (each constant under rotation) plus the farthest tool point from the flange."""
    chain = geometry.chain
    origins = frame_origins(chain, np.zeros(chain.dof), geometry.ee_points)
    n = chain.dof
    steps = np.linalg.norm(np.diff(origins[:n + 1], axis=0), axis=-1)  # (n,)
    tool = (float(np.linalg.norm(origins[n + 1:] - origins[n], axis=-1).max())
            if len(origins) > n + 1 else 0.0)
    after = np.concatenate([np.cumsum(steps[::-1])[::-1], [0.0]])  # from origin j on
    return after[:n] + tool


def stopping_travel_mm(velocity_rad_s: np.ndarray, deceleration_rad_s2: np.ndarray,
                       reaction_s: float, levers: np.ndarray, *,
                       rest_gap_rad: np.ndarray | None = None,
                       next_command_rad: np.ndarray | float = 0.0) -> float:
    """How far any point of the arm can still move before it stands, mm: each joint goes
    on for ``reaction_s`` at its speed, then brakes at ``deceleration_rad_s2``
    (v^2 / 2a), and a joint turning by an angle moves no point farther than the angle
    times its lever (:func:`levers_mm`).

    ``rest_gap_rad``: per joint, how far the position command in force still takes it
    (NaN: no such command): a module commanded to a position stops there, however long
    the host is silent; one more command may follow before the next reading
    (``next_command_rad``, its longest step), and a joint too fast to stop short of its
    target still brakes at most v^2 / 2a beyond it."""
    v = np.abs(np.asarray(velocity_rad_s, dtype=float))
    braking = v * v / (2.0 * np.asarray(deceleration_rad_s2, dtype=float))
    angle = v * reaction_s + braking
    if rest_gap_rad is not None:
        held = np.maximum(np.abs(np.asarray(rest_gap_rad, dtype=float)) + next_command_rad,
                          braking)
        angle = np.where(np.isnan(held), angle, np.minimum(angle, held))
    return float(angle @ levers)
