"""``<run>/run.mcap`` of a campaign run with several arms: every arm in one ROS 2 bag.

Each arm's topics are namespaced by its arm id (docs/ros2.md, docs/two-arms.md):

``/<id>/joint_states``, ``/<id>/joint_commands``, ``/<id>/planned``  as one arm's run.mcap
``/<id>/events``   std_msgs/String: that arm's events.jsonl lines
``/<id>/markers``  visualization_msgs/MarkerArray: its guards, obstacles, capsules
``/tf``            every arm's links (frames ``<id>/base``, ``<id>/j1`` ... ``<id>/end_effector``)
``/tf_static``     each arm's base in the facility frame (``facility`` -> ``<id>/base``,
                   the campaign's ``base``), stamped at the run's start

Every stamp is on the run's one time base (:mod:`seqrun.service.time_base`: each arm's
event at ``t`` lies at its ``start_epoch_s + t``), and the messages are written in log-time
order: each arm's records are queued and merged (a record is written once every arm still
running has got as far, or once it is :data:`MERGE_LAG_S` older than the newest; a plan,
known only when its move ends, is logged then, stamped at the move's start).

:class:`ArmsMcapLog` writes it live: each arm's run log hands its events to that arm's
face (:meth:`ArmsMcapLog.for_arm`, the same ``put``/``close`` as one arm's
:class:`~seqrun.service.mcap_log.McapLog`), never waiting; one thread converts and writes.
:func:`rebuild_arms_mcap` writes it afterwards from the arms' events.jsonl (``seqrun report
<run> --mcap``).
"""

from __future__ import annotations

import heapq
import itertools
import json
import re
import shutil
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from seqrun.ros_messages import cdr
from seqrun.ros_messages.from_events import EventTranslator
from seqrun.ros_messages.names import EVENTS_TOPIC, MARKERS_TOPIC, RosNames
from seqrun.ros_messages.ros_fields import TF_MESSAGE, topics
from seqrun.ros_messages.values import Transform, quaternion_xyzw, stamp_ns
from seqrun.service.mcap_log import (DEFAULT_DISTRIBUTION, QUEUE_SIZE, McapFolder,
                                     QueuedBagWriter, serialized_record)

if TYPE_CHECKING:
    import numpy as np

    from seqrun.arm.description import ArmDescription

#: The common frame of a campaign's arms (seqrun.toml ``[arms.ID] base``).
FACILITY_FRAME = "facility"
TF_STATIC_TOPIC = "/tf_static"
#: A quiet arm (waiting, asking) holds the others' messages back at most this long (s).
MERGE_LAG_S = 1.0
#: The summary of a campaign run (seqrun/service/arms_records.py writes it).
ARMS_SUMMARY = "arms.json"

#: What an arm's face queues when that arm's run has ended.
_ARM_ENDED = object()


def arm_namespace(arm_id: str) -> str:
    """An arm id as a ROS name token (``A`` -> ``A``; ``-`` is not one: ``_``)."""
    return re.sub(r"[^A-Za-z0-9_]", "_", arm_id)


def arm_renames(names: RosNames) -> dict[str, str]:
    """One arm's own names, in the combined bag, of the topics one arm's run.mcap calls
    seqrun's (its events and markers)."""
    return {EVENTS_TOPIC: f"/{names.namespace}/events",
            MARKERS_TOPIC: f"/{names.namespace}/markers"}


def arm_topics(names: RosNames) -> dict[str, str]:
    """One arm's topics in the combined bag (the per-arm names of its events and markers)
    and their types; /tf is shared."""
    own = arm_renames(names)
    return {own.get(topic, topic): msgtype for topic, msgtype in topics(names).items()}


class ArmsBag(McapFolder):
    """The combined bag (rosbags' writer, MCAP storage); :meth:`write_event` per arm, in
    each arm's order; :meth:`arm_ended` when an arm has no more; :meth:`close` ends it."""

    def __init__(self, folder: Path, arms: Mapping[str, ArmDescription],
                 bases: Mapping[str, np.ndarray], start_epoch_s: float, *,
                 distribution: str = DEFAULT_DISTRIBUTION) -> None:
        self.names = {a: RosNames.of(arm, arm_namespace(a)) for a, arm in arms.items()}
        self.translators = {a: EventTranslator(arm, self.names[a]) for a, arm in arms.items()}
        self._rename = {a: arm_renames(n) for a, n in self.names.items()}
        #: Records logged later than their arm's previous one would allow (kept in order).
        self.reordered = 0
        wanted = {TF_STATIC_TOPIC: TF_MESSAGE}
        for names in self.names.values():
            wanted.update(arm_topics(names))
        super().__init__(folder, wanted, distribution)
        # the merge: (log_ns, order, topic, data), each arm's last log time, who has ended
        self._heap: list[tuple[int, int, str, bytes | memoryview]] = []
        self._order = itertools.count()
        self._last = {a: -1 for a in arms}
        self._ended: set[str] = set()
        self._started: set[str] = set()
        self._written = stamp_ns(start_epoch_s)
        self._lag_ns = stamp_ns(MERGE_LAG_S)
        self._put(TF_STATIC_TOPIC, self._written, cdr.tf_message(self._written, [
            facility_transform(self.names[a].base_frame, bases[a]) for a in arms]))

    # -- feeding -------------------------------------------------------------------------
    def write_event(self, arm_id: str, event: Mapping[str, Any]) -> None:
        names = self.names[arm_id]
        rename = self._rename[arm_id]
        cap = None
        if event.get("type") == "run_started" and arm_id not in self._started:
            # The events before it (the zero reference) are timed from the executor's
            # making, not from the run's t = 0: they are logged with run_started.
            self._started.add(arm_id)
            cap = stamp_ns(float(event["start_epoch_s"]) + float(event.get("t") or 0.0))
        for record in self.translators[arm_id].translate(event):
            log = record.log_ns if cap is None else min(record.log_ns, cap)
            log = max(log, self._last[arm_id])   # a plan: logged when its move ended
            self._last[arm_id] = log
            for topic, data in serialized_record(record, names, self.serializer):
                self._queue(log, rename.get(topic, topic), data)
        self._flush()

    def arm_ended(self, arm_id: str) -> None:
        """The arm's events are over: it holds the others back no longer."""
        if arm_id in self._ended:
            return
        for record in self.translators[arm_id].finish():
            log = max(record.log_ns, self._last[arm_id])
            self._last[arm_id] = log
            for topic, data in serialized_record(record, self.names[arm_id], self.serializer):
                self._queue(log, self._rename[arm_id].get(topic, topic), data)
        self._ended.add(arm_id)
        self._flush()

    def _queue(self, log_ns: int, topic: str, data: bytes | memoryview) -> None:
        heapq.heappush(self._heap, (log_ns, next(self._order), topic, data))

    def _flush(self, everything: bool = False) -> None:
        running = [last for a, last in self._last.items() if a not in self._ended]
        newest = max(self._last.values())
        until = max(min(running) if running else newest, newest - self._lag_ns)
        while self._heap and (everything or self._heap[0][0] <= until):
            log_ns, _, topic, data = heapq.heappop(self._heap)
            if log_ns < self._written:   # an arm later than the merge allowed for
                self.reordered += 1
                log_ns = self._written
            self._put(topic, log_ns, data)

    def _put(self, topic: str, log_ns: int, data: bytes | memoryview) -> None:
        super()._put(topic, log_ns, data)
        self._written = log_ns

    # -- the end ---------------------------------------------------------------------------
    def close(self) -> Path:
        """Write what is held, end the bag, put its MCAP file at ``folder/run.mcap``."""
        for arm_id in list(self.names):
            self.arm_ended(arm_id)
        self._flush(everything=True)
        return self._finish()


def facility_transform(child: str, base: np.ndarray) -> Transform:
    """The arm's base (4x4, mm) in the facility frame, as a tf transform (m): ``/tf_static``
    of the combined bag and of Foxglove live serving several arms."""
    return Transform(FACILITY_FRAME, child,
                     (float(base[0, 3]) / 1000.0, float(base[1, 3]) / 1000.0,
                      float(base[2, 3]) / 1000.0), quaternion_xyzw(base[:3, :3]))


class ArmsMcapLog(QueuedBagWriter):
    """``<run>/run.mcap`` of a campaign run, written live by a thread of its own from what
    every arm's run log hands its face (:meth:`for_arm`); never waits, never stops a run
    (a full queue drops and counts, a failing disk stops the file, each said once). It is
    ended (:meth:`close`) after every arm's run has ended."""

    def __init__(self, folder: Path, arms: Mapping[str, ArmDescription],
                 bases: Mapping[str, np.ndarray], start_epoch_s: float, *,
                 distribution: str = DEFAULT_DISTRIBUTION,
                 on_error: Callable[[str], None] | None = None,
                 queue_size: int = QUEUE_SIZE) -> None:
        self.distribution = distribution
        self._faces = {a: _ArmFace(self, a, RosNames.of(arm, arm_namespace(a)))
                       for a, arm in arms.items()}
        super().__init__(folder, lambda: ArmsBag(Path(folder), arms, bases, start_epoch_s,
                                                 distribution=distribution),
                         thread_name="seqrun-arms-mcap", on_error=on_error,
                         queue_size=queue_size)

    def for_arm(self, arm_id: str) -> _ArmFace:
        return self._faces[arm_id]

    @property
    def dropped(self) -> int:
        return sum(face.dropped for face in self._faces.values())

    @property
    def reordered(self) -> int:
        return self._bag.reordered if self._bag is not None else 0

    def _put(self, face: _ArmFace, item: Any) -> None:
        if not self._offer((face.arm_id, item)):
            face.dropped += 1

    def _write(self, bag: ArmsBag, item: tuple[str, Any]) -> None:
        arm_id, event = item
        if event is _ARM_ENDED:
            bag.arm_ended(arm_id)
        else:
            bag.write_event(arm_id, event)


class _ArmFace:
    """One arm's side of :class:`ArmsMcapLog`, as its run log sees a run.mcap writer:
    ``put`` each event, ``close`` when the arm's run ends (the file stays open for the
    others), ``dropped`` and ``error`` for the arm's report."""

    def __init__(self, log: ArmsMcapLog, arm_id: str, names: RosNames) -> None:
        self.log, self.arm_id, self.names = log, arm_id, names
        self.dropped = 0
        self._ended = False

    @property
    def distribution(self) -> str:
        return self.log.distribution

    @property
    def error(self) -> str | None:
        return self.log.error

    def put(self, event: Mapping[str, Any]) -> None:
        if not self._ended:
            self.log._put(self, event)

    def close(self) -> None:
        if not self._ended:
            self._ended = True
            self.log._put(self, _ARM_ENDED)


# -- afterwards: from the arms' events.jsonl --------------------------------------------------
def rebuild_arms_mcap(folder: Path) -> tuple[Path, dict[str, int]]:
    """``seqrun report <run> --mcap`` of a campaign run (``arms.json`` at its top): write
    ``<run>/run.mcap`` anew from every arm's ``<run>/<id>/events.jsonl``, merged on the
    run's one time base. Raises :class:`seqrun.errors.UserInputError` for a folder that
    cannot give one."""
    from seqrun.arm.between_arms import base_transform
    from seqrun.arm.description import ArmDescription
    from seqrun.errors import UserInputError

    folder = Path(folder)
    try:
        summary = json.loads((folder / ARMS_SUMMARY).read_text(encoding="utf-8"))
        arm_entries = dict(summary["arms"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise UserInputError(f"{folder / ARMS_SUMMARY}: not a campaign run's summary "
                             f"({exc})") from None
    arms: dict[str, ArmDescription] = {}
    bases: dict[str, np.ndarray] = {}
    streams: list[list[tuple[float, str, dict]]] = []
    starts: list[float] = []
    for arm_id, entry in arm_entries.items():
        part = folder / str((entry or {}).get("part") or arm_id)
        from seqrun.runfolder.names import EVENTS_NAME, events_path

        log = events_path(part) or part / EVENTS_NAME
        events = _events(log)
        started = next((e for e in events if e.get("type") == "run_started"), None)
        if started is None or "start_epoch_s" not in started:
            raise UserInputError(f"{log}: no run_started with its time "
                                 "base; nothing to write run.mcap from")
        try:
            arms[arm_id] = ArmDescription.model_validate(started.get("arm"))
        except ValueError:
            raise UserInputError(f"{log}: the run did not record its "
                                 "arm") from None
        base = (entry or {}).get("base") or {}
        bases[arm_id] = base_transform(base.get("position_mm") or (0, 0, 0),
                                       base.get("rpy_deg") or (0, 0, 0))
        epoch0 = float(started["start_epoch_s"])    # the wall-clock time of the arm's t = 0
        starts.append(float(started["start_epoch_s"]))
        stream, at = [], -float("inf")
        for event in events:   # each arm in its own order: a key that never goes back
            at = max(at, epoch0 + float(event.get("t") or 0.0))
            stream.append((at, arm_id, event))
        streams.append(stream)
    time_base = summary.get("time_base") or {}
    start = float(time_base.get("epoch_s", min(starts)))
    distribution = (summary.get("ros") or {}).get("distribution") or DEFAULT_DISTRIBUTION
    bag = ArmsBag(folder, arms, bases, min(start, *starts), distribution=distribution)
    try:
        for _, arm_id, event in heapq.merge(*streams, key=lambda item: item[0]):
            bag.write_event(arm_id, event)
    except BaseException:
        bag.abort()
        shutil.rmtree(bag.partial, ignore_errors=True)
        raise
    return bag.close(), dict(bag.counts)


def is_arms_run(folder: Path) -> bool:
    """Whether ``folder`` is a campaign run with several arms (``arms.json`` at its top)."""
    return (Path(folder) / ARMS_SUMMARY).is_file()


def _events(path: Path) -> list[dict]:
    from seqrun.runfolder.logfile import read_lines

    if not path.is_file():
        return []
    out = []
    for raw in read_lines(path):
        try:
            event = json.loads(raw)
        except ValueError:
            continue
        if isinstance(event, dict):
            out.append(event)
    return out

