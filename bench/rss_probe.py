"""Where a process that runs one sequence after another keeps its memory: a probe.

    .venv/bin/python bench/rss_probe.py [--runs 40] [--moves 2 4] [--seed 1] [--faults]
        [--off report mcap ...] [--out bench/results/rss_probe.json]

The soak's runs (bench/soak.py: random valid sequences through the real CLI in this
process, ``seqrun run FILE --virtual-time --yes --plain [--sim-fault SPEC] --log-dir DIR``),
short ones by default (``--moves``: the growth is per run, not per virtual hour), after the
soak's two warm-up runs. After each run (and a full collection) it prints:

- ``rss`` the resident set, and its anonymous part (``anon``: the heaps; the rest is files
  mapped, e.g. shared libraries and fonts);
- Python's view: ``blocks`` (``sys.getallocatedblocks``), ``objs`` (``gc.get_objects``),
  ``thr`` Python threads / OS threads;
- glibc's view (``mallinfo2``, over every arena): ``arena`` the heap bytes taken from the
  system with brk/mmap'ed heaps, ``inuse`` the bytes malloc has handed out, ``free`` the
  free bytes it keeps, ``mmap`` the bytes in blocks mmap'ed one each; and the size of each
  arena (``malloc_info``: the main one first, then those of threads);
- ``pyar`` Python's own arenas (pymalloc, 1 MiB each, outside malloc's);
- the signal handlers of SIGINT, SIGTERM, SIGHUP and SIGQUIT, when they differ from
  before the first run.

At the end: the least-squares slope per run (KB) of each figure over the runs after the
first, and the slope per virtual hour of the RSS. ``--off`` switches parts of the run off
to bisect the growth: ``report`` (``--no-report``: no report.html), ``mcap`` (the project's
seqrun.toml says ``[ros] mcap = false``). Results go to ``--out`` as JSON.

A measuring tool, not a product: it reads glibc's statistics through ctypes.
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import os
import random
import re
import shutil
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import RESULTS, machine, write_json  # noqa: E402
from soak import FaultDeck, make_project, random_sequence, run_cli, warm_up  # noqa: E402

PARTS = ("report", "mcap")
SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")
                if hasattr(signal, n))


class Mallinfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]


_libc = ctypes.CDLL(None)
_mallinfo2 = getattr(_libc, "mallinfo2", None)
if _mallinfo2 is not None:
    _mallinfo2.restype = Mallinfo2
_open_memstream = _libc.open_memstream
_open_memstream.restype = ctypes.c_void_p
_open_memstream.argtypes = [ctypes.POINTER(ctypes.c_char_p), ctypes.POINTER(ctypes.c_size_t)]
_libc.fclose.argtypes = [ctypes.c_void_p]
_libc.malloc_info.argtypes = [ctypes.c_int, ctypes.c_void_p]
_libc.free.argtypes = [ctypes.c_void_p]


def malloc_heaps() -> list[int]:
    """The size (KB) of each of glibc malloc's arenas (``malloc_info``): the main one
    (brk) first, then one per arena threads were given."""
    buf, size = ctypes.c_char_p(), ctypes.c_size_t()
    stream = _open_memstream(ctypes.byref(buf), ctypes.byref(size))
    _libc.malloc_info(0, stream)
    _libc.fclose(stream)
    text = ctypes.string_at(buf, size.value).decode()
    _libc.free(ctypes.cast(buf, ctypes.c_void_p))
    heaps = text.split("<heap nr=")[1:]
    return [int(re.search(r'<system type="current" size="(\d+)"', h)[1]) // 1024
            for h in heaps]


def pymalloc_arenas() -> int:
    """Python's small-object allocator's arenas (1 MiB each, mmap'ed) in use now, from
    ``sys._debugmallocstats`` (it writes to the C stderr)."""
    with tempfile.TemporaryFile() as out:
        saved = os.dup(2)
        try:
            sys.stderr.flush()
            os.dup2(out.fileno(), 2)
            sys._debugmallocstats()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        out.seek(0)
        text = out.read().decode(errors="replace")
    found = re.search(r"# arenas allocated current\s*=\s*([\d,]+)", text)
    return int(found[1].replace(",", "")) if found else -1


def status_kb(*names: str) -> dict[str, int]:
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            key, _, value = line.partition(":")
            if key in names:
                out[key] = int(value.split()[0])
    return out


def sample() -> dict[str, int]:
    gc.collect()
    kb = status_kb("VmRSS", "RssAnon", "RssFile")
    info = _mallinfo2() if _mallinfo2 is not None else None
    return {
        "rss_kb": kb["VmRSS"], "anon_kb": kb["RssAnon"], "file_kb": kb["RssFile"],
        "blocks": sys.getallocatedblocks(), "objects": len(gc.get_objects()),
        "threads": threading.active_count(), "os_threads": len(os.listdir("/proc/self/task")),
        "fds": len(os.listdir("/proc/self/fd")),
        "arena_kb": info.arena // 1024 if info else -1,
        "inuse_kb": info.uordblks // 1024 if info else -1,
        "free_kb": info.fordblks // 1024 if info else -1,
        "mmap_kb": info.hblkhd // 1024 if info else -1,
        "heaps_kb": malloc_heaps(),
        "py_arenas": pymalloc_arenas(),
    }


def handlers() -> dict[str, object]:
    return {signal.Signals(s).name: signal.getsignal(s) for s in SIGNALS}


def per_run_slope(values: list[float]) -> float | None:
    """Least-squares slope per run, over the runs after the first."""
    if len(values) < 3:
        return None
    import numpy as np

    y = np.array(values[1:], dtype=float)
    return float(np.polyfit(np.arange(len(y)), y, 1)[0])


def probe(runs: int, *, seed: int, moves: tuple[int, int], faults: bool,
          off: set[str], progress=print) -> dict:
    rng = random.Random(seed)
    deck = FaultDeck(rng, clean=1)
    work = Path(tempfile.mkdtemp(prefix="seqrun-rss-probe-"))
    rows: list[dict] = []
    virtual_s = 0.0
    try:
        sequences = make_project(work / "project")
        if "mcap" in off:
            (work / "project" / "seqrun.toml").write_text("[ros]\nmcap = false\n")
        extra = ["--no-report"] if "report" in off else []
        warm_up(sequences, work)
        before = handlers()
        first = sample()
        progress("   run  virt_s  wall_s    rss   anon   file  blocks  objs  thr   arena"
                 "   inuse    free    mmap pyar  malloc arenas (MB)")
        for n in range(1, runs + 1):
            sequence, planned = random_sequence(rng, sequences, f"probe-{n:04d}", moves)
            fault = deck.draw(planned) if faults else None
            folder = work / f"run-{n:04d}"
            w0 = time.perf_counter()
            result = run_cli(sequence, folder, fault, extra)
            wall = time.perf_counter() - w0
            duration = _duration(folder)
            virtual_s += duration
            shutil.rmtree(folder, ignore_errors=True)
            sequence.unlink()
            s = sample()
            changed = {k: repr(v) for k, v in handlers().items() if v is not before[k]}
            rows.append({"run": n, "exit": result.exit_code, "virtual_s": round(duration, 3),
                         "virtual_h_total": round(virtual_s / 3600, 5), "wall_s": round(wall, 2),
                         **s, **({"handlers_changed": changed} if changed else {})})
            progress(f"{n:6d} {duration:7.1f} {wall:7.2f} {s['rss_kb'] / 1024:6.1f} "
                     f"{s['anon_kb'] / 1024:6.1f} {s['file_kb'] / 1024:6.1f} {s['blocks']:7d} "
                     f"{s['objects'] // 1000:4d}k {s['threads']:2d}/{s['os_threads']:<2d}"
                     f"{s['arena_kb'] / 1024:7.1f} {s['inuse_kb'] / 1024:7.1f} "
                     f"{s['free_kb'] / 1024:7.1f} {s['mmap_kb'] / 1024:7.1f} {s['py_arenas']:4d}  "
                     + " ".join(f"{kb / 1024:.1f}" for kb in s["heaps_kb"])
                     + (f"  handlers changed: {changed}" if changed else "")
                     + (f"  exit {result.exit_code}" if result.exit_code not in (0, 3) else ""))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    keys = ("rss_kb", "anon_kb", "file_kb", "blocks", "objects", "arena_kb", "inuse_kb",
            "free_kb", "mmap_kb", "py_arenas", "os_threads", "fds")
    slopes = {k: per_run_slope([r[k] for r in rows]) for k in keys}
    hours = [r["virtual_h_total"] for r in rows]
    rss_per_h = None
    if len(rows) >= 3:
        import numpy as np

        rss_per_h = float(np.polyfit(hours[1:], [r["rss_kb"] for r in rows[1:]], 1)[0])
    return {"runs": runs, "seed": seed, "moves": list(moves), "faults": faults,
            "off": sorted(off), "after_warm_up": first, "rows": rows,
            "slope_per_run": slopes, "rss_slope_kb_per_virtual_h": rss_per_h,
            "virtual_s": round(virtual_s, 1)}


def _duration(folder: Path) -> float:
    import json

    try:
        return float(json.loads((folder / "report.json").read_text()).get("duration_s") or 0)
    except (OSError, ValueError):
        return 0.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--moves", type=int, nargs=2, default=(2, 4), metavar=("MIN", "MAX"))
    parser.add_argument("--faults", action="store_true",
                        help="the soak's fault deck (default: clean runs only)")
    parser.add_argument("--off", nargs="*", default=[], choices=PARTS)
    parser.add_argument("--out", type=Path, default=RESULTS / "rss_probe.json")
    args = parser.parse_args()
    info = machine()
    result = probe(args.runs, seed=args.seed, moves=tuple(args.moves), faults=args.faults,
                   off=set(args.off))
    s = result["slope_per_run"]
    print("\nslope per run (runs 2..N): " + ", ".join(
        f"{k} {v:+.1f}" for k, v in s.items() if v is not None))
    print(f"RSS slope per virtual hour: {result['rss_slope_kb_per_virtual_h']:.0f} KB/h "
          f"({result['virtual_s']:.0f} s of virtual motion)")
    write_json(args.out, {"machine": info, "load_avg_at_end": os.getloadavg(), **result})
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
