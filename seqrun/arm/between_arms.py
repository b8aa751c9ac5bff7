"""Clearance between two arms' volumes in a common facility frame (pure numpy, no I/O).

Each arm's links and tools are capsules (:class:`seqrun.arm.geometry.Geometry`) in its own
base frame; its base pose in the facility frame (``[arms.ID] base`` of ``seqrun.toml``)
carries them into the common frame, where every capsule of one arm is checked against
every capsule of the other. Clearances are surface to surface, mm, negative when the
volumes overlap, like the guard clearances of one arm.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from seqrun.arm.geometry import Clearance, Geometry, segment_segment
from seqrun.arm.kinematics import matrix_from_rpy

__all__ = ["base_transform", "base_of", "between_arms", "volumes_in_facility"]


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
