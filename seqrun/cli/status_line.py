"""``seqrun status --watch`` into a file or a pipe: one line per refresh.

A live table is for a terminal; written to a file it left only its last frame, cut at 80
columns. Each line is whole and greppable: the local time, every joint's position and state
(a value read before, whose module did not answer this time, marked stale) and the
end-effector position.
"""

from __future__ import annotations

import datetime as _dt


def _number(value) -> str:
    from seqrun.cli.output import fixed

    return "-" if value is None else fixed(value, 3)  # never -0.000


def status_line(status: dict, now: _dt.datetime | None = None) -> str:
    """One refresh of ``seqrun status`` as one line."""
    stamp = (now or _dt.datetime.now()).strftime("%H:%M:%S.%f")[:-3]
    joints = []
    for j in status["joints"]:
        stale = " (stale: no answer)" if j.get("stale") else ""
        joints.append(f"{j['joint']} {_number(j['position_deg'])} {j['state'] or '-'}{stale}")
    ee = status.get("end_effector")
    where = ("ee unknown" if ee is None else
             "ee [" + ", ".join(f"{v:.1f}" for v in ee["position_mm"]) + "] mm")
    return f"{stamp}  " + "  ".join(joints) + f"  {where}"
