"""Reading a large sequence file: libyaml's parser vs PyYAML's pure-Python one, side by side.

    python bench/bench_yaml.py [--steps 10000] [--repeat 5] [--out bench/results/yaml.json]

Composes (``seqrun.yamlsource.load_document``: parse, compose with the limits, convert with
the duplicate-key/tag checks) and loads (``seqrun.schema.load_sequence``: plus pydantic and
the include/pose resolution) one generated file of N steps, alternating the two parsers in
each round so that both see the same machine load. Reports the median and the ratio.
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import statistics
import tempfile
import time
from pathlib import Path

from seqrun import yamlsource
from seqrun.sequence.loader import load_sequence
from seqrun.yamlsource import load_document

ROOT = Path(__file__).resolve().parents[1]


def make_sequence(steps: int) -> str:
    """A start-up, then moves, waits and checkpoints, as a generated test campaign has."""
    lines = ["name: Large", "description: generated for bench_yaml", "steps:",
             "  - include: startup.yaml"]
    kinds = [
        "  - move: {{joints: {{j1: {a}, j2: {b}}}, velocity_scale: 0.5, label: Step {n}}}",
        "  - wait: {{seconds: 0.5, label: Dwell {n}}}",
        "  - move:\n      pose: totem\n      label: Back to Totem {n}",
        "  - checkpoint: {{pose: totem, position_tolerance_mm: 7}}",
    ]
    for n in range(steps - 3):  # the include brings three
        lines.append(kinds[n % len(kinds)].format(n=n, a=(n % 90) - 45, b=(n % 60) - 30))
    return "\n".join(lines) + "\n"


def timed(function, libyaml: bool) -> float:
    yamlsource.USE_LIBYAML = libyaml
    start = time.perf_counter()
    function()
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    if not yamlsource.USE_LIBYAML:
        parser.error("PyYAML was installed without libyaml: nothing to compare")
    with tempfile.TemporaryDirectory() as folder:
        project = Path(folder)
        shutil.copytree(ROOT / "arms", project / "arms")
        shutil.copytree(ROOT / "poses", project / "poses")
        (project / "sequences").mkdir()
        shutil.copy(ROOT / "sequences" / "startup.yaml", project / "sequences")
        path = project / "sequences" / "large.yaml"
        path.write_text(make_sequence(args.steps), encoding="utf-8")
        assert not yamlsource._python_only(path.read_text()), "would not use libyaml"
        results: dict[str, dict[str, list[float]]] = {}
        for what, function in (("compose", lambda: load_document(path)),
                               ("load_sequence", lambda: load_sequence(path))):
            runs: dict[str, list[float]] = {"libyaml": [], "pure_python": []}
            for _ in range(args.repeat):
                runs["libyaml"].append(timed(function, True))
                runs["pure_python"].append(timed(function, False))
            results[what] = runs
        size = path.stat().st_size
    yamlsource.USE_LIBYAML = True
    summary = {
        "steps": args.steps, "file_bytes": size, "repeat": args.repeat,
        "python": platform.python_version(), "machine": platform.machine(),
        "date": time.strftime("%Y-%m-%d %H:%M"),
    }
    print(f"{args.steps} steps ({size / 1e6:.2f} MB), median of {args.repeat}, same run:")
    for what, runs in results.items():
        fast = statistics.median(runs["libyaml"])
        slow = statistics.median(runs["pure_python"])
        summary[what] = {"libyaml_s": round(fast, 3), "pure_python_s": round(slow, 3),
                         "speedup": round(slow / fast, 2)}
        print(f"  {what:14s} libyaml {fast:6.3f} s   pure Python {slow:6.3f} s   "
              f"{slow / fast:4.1f}x")
    if args.out is not None:
        args.out.write_text(json.dumps(summary, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
