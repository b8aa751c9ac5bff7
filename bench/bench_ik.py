"""Inverse kinematics on random reachable poses: seqrun's solver side by side with ikpy.

Poses: forward kinematics of N random configurations inside the joint limits (j3 at its
locked value), fixed random seed, so the poses and every success/accuracy number are
deterministic. Each pose is solved twice: seeded from Totem (all zeros) and from a nearby
configuration (the true one plus N(0, 5°) noise, clipped to the limits). A solve succeeds
when forward kinematics of the answer is within 1e-3 mm and 1e-6 rad of the pose and every
joint is inside its limits (solutions outside the limits are counted separately).

ikpy (``pip install ikpy``; for this benchmark only, not a dependency of seqrun) gets the
same chain built from the arm description (metres), the same poses and seeds, the locked
joint inactive. Times are wall-clock per solve on one core: indicative only on a shared
machine; the success rates are not affected by load.

Goal (issue 14): >= 99.9 % success, median <= 1 ms, ahead of ikpy on both.

Run: ``.venv/bin/python bench/bench_ik.py [--n 1000] [--no-ikpy] [--out FILE]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from seqrun.arm.description import load_arm  # noqa: E402
from seqrun.arm.ik import IkSolver, Unreachable  # noqa: E402
from seqrun.arm.kinematics import Chain, fk, orientation_error  # noqa: E402

POSITION_TOL_MM = 1e-3
ANGLE_TOL_RAD = 1e-6


def poses(arm, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    limits = np.array([j.limits_deg for j in arm.joints])
    q = rng.uniform(limits[:, 0], limits[:, 1], (n, arm.dof))
    for i, joint in enumerate(arm.joints):
        if joint.locked is not None:
            q[:, i] = joint.locked
    return q, fk(Chain.from_arm(arm), np.radians(q))


def seeds(arm, q_true: np.ndarray, rng: np.random.Generator) -> dict[str, np.ndarray]:
    limits = np.array([j.limits_deg for j in arm.joints])
    locked = np.array([j.locked is not None for j in arm.joints])
    near = np.clip(q_true + rng.normal(0.0, 5.0, q_true.shape), limits[:, 0], limits[:, 1])
    near[:, locked] = q_true[:, locked]
    totem = np.zeros_like(q_true)
    totem[:, locked] = q_true[:, locked]
    return {"totem": totem, "near": near}


def judge(arm, chain, targets, answers) -> dict:
    """Success / accuracy / limit counts of answers (deg, NaN where the solver gave up)."""
    limits = np.array([j.limits_deg for j in arm.joints])
    found = ~np.isnan(answers).any(axis=1)
    inside = np.all((answers >= limits[:, 0] - 1e-9) & (answers <= limits[:, 1] + 1e-9), axis=1)
    reached = fk(chain, np.radians(np.nan_to_num(answers)))
    dist = np.linalg.norm(reached[:, :3, 3] - targets[:, :3, 3], axis=1)
    angle = orientation_error(reached, targets)
    ok = found & inside & (dist <= POSITION_TOL_MM) & (angle <= ANGLE_TOL_RAD)
    return {"success_rate": float(ok.mean()), "failures": int((~ok).sum()),
            "answered_outside_limits": int((found & ~inside).sum()),
            "answered_but_inaccurate": int((found & inside & ~ok).sum())}


def timing(times_s: list[float]) -> dict:
    t = np.array(times_s) * 1e3
    return {"median_ms": round(float(np.median(t)), 4), "p99_ms": round(float(np.percentile(t, 99)), 4),
            "mean_ms": round(float(t.mean()), 4)}


def run_seqrun(arm, targets, seed_sets) -> dict:
    solver = IkSolver(arm)
    chain = Chain.from_arm(arm)
    out = {}
    for name, seed in seed_sets.items():
        answers = np.full(seed.shape, np.nan)
        times = []
        for k, target in enumerate(targets):
            t0 = time.perf_counter()
            try:
                answers[k] = solver.solve(target, seed[k]).joints_deg
            except Unreachable:
                pass
            times.append(time.perf_counter() - t0)
        out[name] = {**judge(arm, chain, targets, answers), **timing(times)}
    return out


def ikpy_chain(arm):
    from ikpy.chain import Chain as IkpyChain
    from ikpy.link import OriginLink, URDFLink

    kin = arm.kinematics
    frames = [kin.base, *kin.links]
    links = [OriginLink()]
    for joint, frame in zip(arm.joints, frames):
        links.append(URDFLink(name=joint.name, origin_translation=np.array(frame.xyz_mm) / 1000,
                              origin_orientation=np.radians(frame.rpy_deg),
                              rotation=np.array([0.0, 0.0, 1.0]),
                              bounds=tuple(np.radians(joint.limits_deg))))
    links.append(URDFLink(name="tool", origin_translation=np.array(kin.tool.xyz_mm) / 1000,
                          origin_orientation=np.radians(kin.tool.rpy_deg), joint_type="fixed"))
    mask = [False] + [j.locked is None for j in arm.joints] + [False]
    return IkpyChain(name=arm.name, links=links, active_links_mask=mask)


def run_ikpy(arm, targets, seed_sets) -> dict:
    chain_ikpy = ikpy_chain(arm)
    chain = Chain.from_arm(arm)
    out = {}
    for name, seed in seed_sets.items():
        answers = np.full(seed.shape, np.nan)
        times = []
        for k, target in enumerate(targets):
            frame = target.copy()
            frame[:3, 3] /= 1000
            initial = np.concatenate([[0.0], np.radians(seed[k]), [0.0]])
            t0 = time.perf_counter()
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    result = chain_ikpy.inverse_kinematics_frame(
                        frame, initial_position=initial, orientation_mode="all")
                answers[k] = np.degrees(result[1:-1])
            except Exception:  # noqa: BLE001 - a failed solve is a failure, whatever raised
                pass
            times.append(time.perf_counter() - t0)
        out[name] = {**judge(arm, chain, targets, answers), **timing(times)}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000, help="number of poses (default 1000)")
    parser.add_argument("--seed", type=int, default=14, help="random seed of the poses")
    parser.add_argument("--arm", default=str(ROOT / "arms" / "lwa3.yaml"))
    parser.add_argument("--no-ikpy", action="store_true", help="skip ikpy")
    parser.add_argument("--out", type=Path, help="write the results as JSON here")
    args = parser.parse_args(argv)
    arm = load_arm(args.arm)
    rng = np.random.default_rng(args.seed)
    q_true, targets = poses(arm, args.n, rng)
    seed_sets = seeds(arm, q_true, rng)
    results = {"poses": args.n, "seed": args.seed, "arm": arm.name,
               "criterion": {"position_mm": POSITION_TOL_MM, "angle_rad": ANGLE_TOL_RAD},
               "load_average": os.getloadavg(), "seqrun": run_seqrun(arm, targets, seed_sets)}
    if not args.no_ikpy:
        try:
            import ikpy  # noqa: F401
        except ImportError:
            print("ikpy is not installed (pip install ikpy): skipped", file=sys.stderr)
        else:
            results["ikpy_version"] = ikpy.__version__
            results["ikpy"] = run_ikpy(arm, targets, seed_sets)
    print(f"IK on {args.n} random reachable poses of {arm.name} (load average "
          f"{results['load_average'][0]:.1f}; times are indicative)")
    print(f"{'solver':8s} {'seed':6s} {'success':>9s} {'outside':>8s} {'median ms':>10s} "
          f"{'p99 ms':>9s}")
    for solver in ("seqrun", "ikpy"):
        for seed_name, r in results.get(solver, {}).items():
            print(f"{solver:8s} {seed_name:6s} {r['success_rate'] * 100:8.2f}% "
                  f"{r['answered_outside_limits']:8d} {r['median_ms']:10.3f} {r['p99_ms']:9.3f}")
    if args.out:
        args.out.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
