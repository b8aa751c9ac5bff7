"""Instructions of the dry run of ``seqrun validate sequences/opsafe.yaml``, alone.

Runs, under valgrind's callgrind, one process that does the static check of the sequence
(as ``seqrun validate --static`` does) and imports the dry run's modules, then the same
plus one dry run (:func:`seqrun.service.dryrun.dry_run`, as ``seqrun validate`` calls it, caches
cold: a fresh process). The difference is the dry run's own cost; divided by the frames
it put on the simulated wire it gives the instructions per frame. Instruction counts do
not depend on the host's load, so before/after figures can be taken on a busy machine.

Also measured: the whole command, ``seqrun validate --static`` vs ``seqrun validate`` as
processes (``python -m seqrun``), whose difference is the dry run's increment as the
operator pays it (the dry run's modules' imports included).

``--compare DIR``: the same in another checkout (e.g. ``git worktree add /tmp/before
main``). ``--digest``: no valgrind; prints a SHA-256 of every frame delivered on the dry
run's wire (exact delivery time, sender, id, data) and of the dry run's report (wall time
left out), to check that a change leaves the dry run bit-identical (compare with
``--compare``): 29 dry runs (:data:`DIGEST_CASES`: both sequences, every fault kind,
ramp and step mode), one line each and one digest over them all; with ``--compare`` it
says whether the two checkouts' digests are equal (exit 1 when not).

Run: ``.venv/bin/python bench/dryrun_instructions.py [--compare DIR] [--digest]
[--sequence FILE]``
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def inner(sequence: str, dry_runs: int, digest: bool) -> None:
    """The measured process: static check, dry-run imports, ``dry_runs`` dry runs."""
    sys.path.insert(0, os.getcwd())
    from seqrun.sequence.checks import static_check

    check = static_check(Path(sequence))
    assert check.valid, check.errors
    import seqrun.service.dryrun as dryrun

    if digest and dry_runs:
        digest_matrix(sequence)
        return
    opened = []
    if dry_runs:
        real_open = dryrun.open_connection

        def capture(**kwargs):
            connection = real_open(**kwargs)
            network = connection.bus.network
            opened.append((network, network.attach(name="digest-sniffer")
                           if digest else None))
            return connection

        dryrun.open_connection = capture
    for _ in range(dry_runs):
        run = dryrun.dry_run(check.loaded, check.arm, check.start_deg)
        assert run.passed, run.result.message
        network, sniffer = opened[-1]
        line = {"frames": network.frames_transmitted, "simulated_s": run.simulated_s}
        if digest:
            wire = hashlib.sha256()
            while sniffer._inbox:
                f = sniffer._inbox.popleft()
                wire.update(f"{f.timestamp!r} {f.sender} {f.can_id:03X} {f.data.hex()}\n"
                            .encode())
            report = run.as_dict()
            del report["wall_s"], report["speedup"]
            line["wire_sha256"] = wire.hexdigest()
            line["report_sha256"] = hashlib.sha256(
                json.dumps([report, run.events], sort_keys=True, default=repr).encode()
            ).hexdigest()
        print(json.dumps(line))


#: The digest's cases: (sequence, command mode, fault spec). Both shipped sequences under
#: every fault kind (random acknowledge losses at three rates) in the arm's mode (ramp),
#: and in step mode without and with a fault: 29 dry runs.
DIGEST_FAULTS = (None, "4:tow_error@3", "4:halt@3", "4:no_ack@3", "4:stuck@3", "4:missing@3",
                 "4:drop_acks=0.5@0", "7:drop_acks=0.01@0", "7:drop_acks=0.003@0",
                 "all:halt@10")
DIGEST_CASES = ([(name, None, spec) for name in ("opsafe", "totem") for spec in DIGEST_FAULTS]
                + [(name, "step", spec) for name in ("opsafe", "totem")
                   for spec in (None, "4:tow_error@3", "4:no_ack@3", "7:drop_acks=0.01@0")]
                + [("opsafe", "step", "4:stuck@3")])


def digest_matrix(sequence: str) -> None:
    """Digests of every case of :data:`DIGEST_CASES` (``sequence`` names the folder of the
    shipped sequences) and one over them all: what a change must leave equal."""
    from seqrun.arm.description import load_arm
    from seqrun.arm.poses import pose_joints_deg
    from seqrun.defaults import START_POSE
    from seqrun.sequence.loader import load_sequence
    from seqrun.sim.faults import parse_fault_spec
    import seqrun.service.dryrun as dryrun

    folder = Path(sequence).parent
    opened = []
    real_open = dryrun.open_connection

    def capture(**kwargs):
        connection = real_open(**kwargs)
        network = connection.bus.network
        opened.append((network, network.attach(name="digest-sniffer")))
        return connection

    dryrun.open_connection = capture
    everything = hashlib.sha256()
    for name, mode, spec in DIGEST_CASES:
        loaded = load_sequence(folder / f"{name}.yaml")
        arm = load_arm(loaded.arm_path)
        start = pose_joints_deg(START_POSE, loaded.pose_path or loaded.poses_dir)
        run = dryrun.dry_run(loaded, arm, start, command_mode=mode,
                             faults=[parse_fault_spec(spec)] if spec else [])
        network, sniffer = opened[-1]
        wire = hashlib.sha256()
        while sniffer._inbox:
            f = sniffer._inbox.popleft()
            wire.update(f"{f.timestamp!r} {f.sender} {f.can_id:03X} {f.data.hex()}\n"
                        .encode())
        report = run.as_dict()
        del report["wall_s"], report["speedup"]
        line = {"case": f"{name} {mode or 'ramp'} {spec or '-'}",
                "frames": network.frames_transmitted, "simulated_s": run.simulated_s,
                "passed": run.passed, "wire_sha256": wire.hexdigest()[:16],
                "result_sha256": hashlib.sha256(json.dumps(report, sort_keys=True,
                                                           default=repr).encode()
                                                ).hexdigest()[:16],
                "events_sha256": hashlib.sha256(json.dumps(run.events, sort_keys=True,
                                                           default=repr).encode()
                                                ).hexdigest()[:16]}
        everything.update(json.dumps(line, sort_keys=True).encode())
        print(json.dumps(line), flush=True)
    print(json.dumps({"cases": len(DIGEST_CASES), "all_sha256": everything.hexdigest()}))


def environment(tree: Path) -> dict[str, str]:
    # The normal bytecode cache, as an installed seqrun has (see bench_startup.py).
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(tree)
    env["PYTHONHASHSEED"] = "0"  # set and dict orders, hence counts, the same every run
    # One BLAS thread, as the seqrun program sets it: the pool's idle threads spin for a
    # while, and callgrind counts their instructions too, differently every run.
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    return env


def cli_instructions(tree: Path, sequence: str, static: bool) -> int | None:
    args = ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
            sys.executable, "-m", "seqrun", "validate", *(["--static"] if static else []),
            sequence]
    subprocess.run(args[3:], cwd=tree, env=environment(tree), capture_output=True)  # .pyc
    proc = subprocess.run(args, cwd=tree, env=environment(tree), capture_output=True,
                          text=True)
    match = re.search(r"Collected : (\d+)", proc.stderr)
    return int(match.group(1)) if match else None


def run_inner(tree: Path, sequence: str, dry_runs: int, *, digest: bool = False,
              callgrind: bool = False, echo: bool = False) -> tuple[int | None, dict]:
    args = [sys.executable, str(Path(__file__).resolve()), "--inner", str(dry_runs),
            "--sequence", sequence] + (["--digest"] if digest else [])
    if callgrind:
        args = ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", *args]
    proc = subprocess.run(args, cwd=tree, env=environment(tree), capture_output=True,
                          text=True)
    if proc.returncode != 0:
        raise SystemExit(f"{tree}: exit {proc.returncode}\n{proc.stderr[-3000:]}")
    match = re.search(r"Collected : (\d+)", proc.stderr)
    lines = [json.loads(x) for x in proc.stdout.splitlines() if x.startswith("{")]
    if echo:
        for line in lines[:-1]:
            print(f"  {json.dumps(line)}")
    return (int(match.group(1)) if match else None), (lines[-1] if lines else {})


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--compare", type=Path, metavar="DIR",
                        help="another seqrun checkout, measured the same way")
    parser.add_argument("--digest", action="store_true",
                        help="print digests of the dry run's frames and report (no valgrind)")
    parser.add_argument("--sequence", default="sequences/opsafe.yaml")
    parser.add_argument("--inner", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.inner is not None:
        inner(args.sequence, args.inner, args.digest)
        return 0
    trees = {"this": ROOT}
    if args.compare is not None:
        trees["compare"] = args.compare.resolve()
    digests: dict[str, str | None] = {}
    for label, tree in trees.items():
        if args.digest:
            _, info = run_inner(tree, args.sequence, 1, digest=True, echo=True)
            print(f"{label:8s} {tree}: {json.dumps(info)}")
            digests[label] = info.get("all_sha256")
            continue
        for _ in range(2):  # first: writes the bytecode cache
            _, info = run_inner(tree, args.sequence, 1)
        static, _ = run_inner(tree, args.sequence, 0, callgrind=True)
        whole, info = run_inner(tree, args.sequence, 1, callgrind=True)
        if static is None or whole is None:
            raise SystemExit("valgrind's callgrind gave no count (is valgrind installed?)")
        frames = info["frames"]
        print(f"{label:8s} {tree}: static + imports {static / 1e6:,.0f} M, with the dry run "
              f"{whole / 1e6:,.0f} M; dry run {(whole - static) / 1e6:,.1f} M instructions "
              f"for {frames} frames ({info['simulated_s']:.3f} s simulated): "
              f"{(whole - static) / frames / 1e3:,.0f} k per frame")
        cli_static = cli_instructions(tree, args.sequence, True)
        cli_whole = cli_instructions(tree, args.sequence, False)
        if cli_static is not None and cli_whole is not None:
            print(f"{'':8s} seqrun validate --static {cli_static / 1e6:,.0f} M, seqrun validate "
                  f"{cli_whole / 1e6:,.0f} M: increment {(cli_whole - cli_static) / 1e6:,.1f} M")
    if len(digests) == 2:
        same = len(set(digests.values())) == 1
        print("digests " + ("EQUAL: the dry runs are bit-identical" if same
                            else "DIFFER: the dry runs are not bit-identical"))
        return 0 if same else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
