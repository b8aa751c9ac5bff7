"""``run.mcap``: the run as a ROS 2 bag (rosbag2, MCAP storage), written as the run goes.

Topics (names and types: :mod:`seqrun.ros_messages`; docs/ros2.md):

``/<arm>/joint_states``    sensor_msgs/JointState, measured, radians, stamped when the
                           modules answered (a setpoint's ``read_t``)
``/<arm>/joint_commands``  sensor_msgs/JointState, what the executor commanded each cycle
                           (the plan's position and velocity)
``/tf``                    tf2_msgs/TFMessage, every link of seqrun's FK at each reading
``/<arm>/planned``         trajectory_msgs/JointTrajectory, one per move, as streamed
``/seqrun/events``         std_msgs/String, one per event: its events.jsonl line
``/seqrun/markers``        visualization_msgs/MarkerArray: guards, obstacles, capsules
``/robot_description``     std_msgs/String, once at the start: the arm as a URDF
                           (``seqrun urdf``, links named as the frames of ``/tf``)

The control loop only hands each event (the dict the run log writes) to :meth:`McapLog.put`:
a bounded queue, never waiting; the conversion (FK, CDR) and the writing are done by the
log's own thread. A full queue drops the event and counts it (said at the end, once);
a failing disk stops this file, is said once and never disturbs the run.

While the run goes, the bag is ``run.mcap.partial/run/`` (rosbags writes a bag folder, its
MCAP file named after the folder: ``run.mcap``, the name its rosbag2 metadata gives); at
the end that file becomes ``run.mcap`` beside the other run files and the folder goes. A
run killed before that leaves ``run.mcap.partial/``, whose whole chunks are readable;
``seqrun report RUN_DIR --mcap`` writes ``run.mcap`` anew from events.jsonl.

As rosbag2 writes a bag: chunks compressed with zstd (rosbag2's ``zstd_fast`` storage
preset does the same; rosbags' own zstd, no further dependency), and every channel's
``offered_qos_profiles`` (:func:`offered_qos`): reliable, keep-last; transient local for
``/tf_static`` and ``robot_description``, so that a player latches them as their
publishers did.
"""

from __future__ import annotations

import queue
import shutil
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from seqrun.ros_messages import cdr
from seqrun.ros_messages.from_events import (EventLine, EventTranslator, Frames, Joints,
                                             Shapes)
from seqrun.ros_messages.names import EVENTS_TOPIC, MARKERS_TOPIC, TF_TOPIC, RosNames
from seqrun.ros_messages.ros_fields import messages, topics

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription

MCAP_NAME = "run.mcap"
PARTIAL_NAME = "run.mcap.partial"
#: The bag folder inside ``run.mcap.partial/``: rosbags names the MCAP file after its
#: folder, so this stem gives ``run.mcap`` (in the file and in its rosbag2 metadata).
BAG_STEM = "run"
#: How run.mcap's chunks are compressed: "zstd" (as rosbag2's zstd presets) or "none".
COMPRESSIONS = ("zstd", "none")
DEFAULT_COMPRESSION = "zstd"
#: ROS 2 distributions run.mcap can be written for (seqrun.toml ``[ros] distribution``).
DISTRIBUTIONS = ("humble", "jazzy", "kilted")
DEFAULT_DISTRIBUTION = "jazzy"
#: Events waiting for the writer thread; beyond this they are dropped (counted).
QUEUE_SIZE = 20_000
#: The URDF's topic, as robot_state_publisher names it.
ROBOT_DESCRIPTION_TOPIC = "/robot_description"
ROBOT_DESCRIPTION_TYPE = "std_msgs/msg/String"

_STOP = object()

#: Topics whose publishers latch (transient local): a late subscriber still gets them.
LATCHED_TOPICS = ("/tf_static", "robot_description")


def offered_qos(topic: str) -> Any:
    """The QoS profile rosbag2 records for ``topic`` (rosbags' ``Qos``), as seqrun's node
    offers it: reliable, keep last; transient local with depth 1 for a latched topic
    (``/tf_static``, ``.../robot_description``), volatile otherwise; no deadline, lifespan
    or lease (ROS 2's "infinite", as rosbag2 writes it)."""
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)

    infinite = QosTime(9223372036, 854775807)
    latched = topic == "/tf_static" or topic.rstrip("/").endswith("robot_description")
    depth = 1 if latched else 100 if topic in (TF_TOPIC, EVENTS_TOPIC) else 10
    return Qos(QosHistory.KEEP_LAST, depth, QosReliability.RELIABLE,
               QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
               infinite, infinite, QosLiveliness.AUTOMATIC, infinite, False)


def typestore_of(distribution: str) -> Any:
    """rosbags' message definitions of a ROS 2 distribution."""
    from rosbags.typesys import Stores, get_typestore

    if distribution not in DISTRIBUTIONS:
        raise ValueError(f"unknown ROS 2 distribution {distribution!r} "
                         f"(one of {', '.join(DISTRIBUTIONS)})")
    return get_typestore(getattr(Stores, f"ROS2_{distribution.upper()}"))


def distribution_of(project: Any) -> str:
    """The ROS 2 distribution a campaign's run.mcap is written for (its seqrun.toml's
    ``[ros] distribution``; Jazzy without one)."""
    ros = getattr(getattr(project, "config", None), "ros", None)
    return str(ros.distribution) if ros is not None else DEFAULT_DISTRIBUTION


class MessageBuilder:
    """ROS messages of rosbags' typestore from nested dicts of fields: a field left out
    takes its type's default (0, "", False, empty, or the nested message's defaults)."""

    def __init__(self, typestore: Any) -> None:
        import numpy as np

        from rosbags.typesys.base import Nodetype

        self.store = typestore
        self._defaults: dict[str, Any] = {}
        self._np = np
        self._node = Nodetype
        self._numeric = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8,
                         "int8": np.int8, "uint8": np.uint8, "int16": np.int16,
                         "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32,
                         "int64": np.int64, "uint64": np.uint64, "float32": np.float32,
                         "float64": np.float64}

    def build(self, msgtype: str, fields: Mapping[str, Any] | None = None) -> Any:
        if not fields:   # a default message: made once (messages are never changed here)
            made = self._defaults.get(msgtype)
            if made is None:
                made = self._defaults[msgtype] = self._build(msgtype, {})
            return made
        return self._build(msgtype, fields)

    def _build(self, msgtype: str, fields: Mapping[str, Any]) -> Any:
        _, defs = self.store.fielddefs[msgtype]
        values = {name: self._value(desc, fields.get(name)) for name, desc in defs}
        return self.store.types[msgtype](**values)

    def _value(self, desc: Any, given: Any) -> Any:
        node, detail = desc
        if node == self._node.BASE:
            base = detail[0]
            if base == "string":
                return "" if given is None else str(given)
            if base in ("float32", "float64"):
                return 0.0 if given is None else float(given)
            if base == "bool":
                return bool(given)
            return 0 if given is None else int(given)
        if node == self._node.NAME:
            return self.build(detail, given)
        (inner_node, inner), size = detail
        if inner_node == self._node.BASE and inner[0] != "string":
            dtype = self._numeric[inner[0]]
            items = [] if given is None else list(given)
            if node == self._node.ARRAY and len(items) < size:
                items += [0] * (size - len(items))
            return self._np.array(items, dtype=dtype)
        items = list(given or [])
        if node == self._node.ARRAY and len(items) < size:
            items += [None] * (size - len(items))
        return [self._value((inner_node, inner), item) for item in items]


class RosSerializer:
    """ROS 2 messages of one distribution (rosbags' typestore): a message from its fields
    as CDR bytes, and a type's message definition as rosbag2 stores it in a bag's schema
    (``ros2msg`` text). run.mcap and Foxglove live's ROS-typed channels
    (``--foxglove-types ros``) both serialize through this, so their bytes agree."""

    def __init__(self, distribution: str = DEFAULT_DISTRIBUTION) -> None:
        self.distribution = distribution
        self.store = typestore_of(distribution)
        self.builder = MessageBuilder(self.store)

    def cdr(self, msgtype: str, fields: Mapping[str, Any] | None) -> bytes | memoryview:
        """A message of rosbags' typestore from its fields, serialized."""
        return self.store.serialize_cdr(self.builder.build(msgtype, fields), msgtype)

    def msgdef(self, msgtype: str) -> str:
        """``msgtype``'s definition with its dependencies, as rosbags' bag writer puts it in
        the MCAP schema of a channel (schema encoding ``ros2msg``)."""
        text, _ = self.store.generate_msgdef(msgtype, ros_version=2)
        return str(text)


def bag_topics(names: RosNames) -> dict[str, str]:
    """Every topic of one arm's run.mcap and its message type."""
    return {**topics(names), ROBOT_DESCRIPTION_TOPIC: ROBOT_DESCRIPTION_TYPE}


def robot_description_cdr(arm: ArmDescription, names: RosNames) -> bytes:
    """``/robot_description``'s message (``std_msgs/String``): the arm as a URDF, its
    links named as the frames of ``/tf``."""
    from seqrun.service.kinematics import robot_description

    return cdr.string(robot_description(arm, f"{names.namespace}/"))


class McapFolder:
    """rosbags' writer (MCAP storage) into ``folder/run.mcap.partial/``, one connection per
    topic of ``wanted`` (topic -> message type); :meth:`_finish` puts its MCAP file at
    ``folder/run.mcap``. The bag of one arm and the bag of several share it."""

    def __init__(self, folder: Path, wanted: Mapping[str, str],
                 distribution: str = DEFAULT_DISTRIBUTION, *,
                 compression: str = DEFAULT_COMPRESSION) -> None:
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

        if compression not in COMPRESSIONS:
            raise ValueError(f"unknown run.mcap compression {compression!r} "
                             f"(one of {', '.join(COMPRESSIONS)})")
        self.folder = Path(folder)
        self.serializer = RosSerializer(distribution)
        self.store = self.serializer.store
        self.builder = self.serializer.builder
        self.counts: dict[str, int] = {}
        self.partial = self.folder / PARTIAL_NAME
        if self.partial.exists():
            shutil.rmtree(self.partial)
        self.writer = Writer(self.partial / BAG_STEM,
                             version=8 if distribution == "humble" else 9,
                             storage_plugin=StoragePlugin.MCAP)
        if compression == "zstd":   # the chunks (rosbag2's "storage" compression)
            self.writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self.writer.open()
        self.connections = {topic: self.writer.add_connection(
                                topic, msgtype, typestore=self.store,
                                offered_qos_profiles=[offered_qos(topic)])
                            for topic, msgtype in wanted.items()}

    def cdr(self, msgtype: str, fields: Mapping[str, Any] | None) -> bytes | memoryview:
        """A message of rosbags' typestore from its fields, serialized."""
        return self.serializer.cdr(msgtype, fields)

    def _put(self, topic: str, log_ns: int, data: bytes | memoryview) -> None:
        self.writer.write(self.connections[topic], log_ns, data)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def _finish(self) -> Path:
        self.writer.close()
        target = self.folder / MCAP_NAME
        (self.partial / BAG_STEM / f"{BAG_STEM}.mcap").replace(target)
        shutil.rmtree(self.partial, ignore_errors=True)
        return target

    def abort(self) -> None:
        try:
            self.writer.abort()
        except Exception:  # noqa: BLE001 - already failing: keep what is on disk
            pass


class BagWriter(McapFolder):
    """The bag of one arm: messages from :mod:`.ros_fields`' records (used by the live log
    and by the rebuild from events.jsonl alike)."""

    def __init__(self, folder: Path, arm: ArmDescription, names: RosNames,
                 distribution: str = DEFAULT_DISTRIBUTION) -> None:
        self.names = names
        self.translator = EventTranslator(arm, names)
        self._urdf: bytes | None = robot_description_cdr(arm, names)
        super().__init__(folder, bag_topics(names), distribution)

    def write_event(self, event: Mapping[str, Any]) -> None:
        records = self.translator.translate(event)
        if records and self._urdf is not None:  # once, with the bag's first messages
            self._put(ROBOT_DESCRIPTION_TOPIC, min(r.log_ns for r in records), self._urdf)
            self._urdf = None
        for record in records:
            self._write(record)

    def _write(self, record: Any) -> None:
        for topic, data in serialized_record(record, self.names, self.serializer):
            self._put(topic, record.log_ns, data)

    def close(self) -> Path:
        """End the bag and put its MCAP file at ``folder/run.mcap``."""
        for record in self.translator.finish():
            self._write(record)
        return self._finish()


def serialized_record(record: Any, names: RosNames, serializer: RosSerializer
                      ) -> list[tuple[str, bytes | memoryview]]:
    """The topic and CDR bytes of every ROS message of ``record``: those of every cycle
    by :func:`encoded_record`, the others by ``serializer``. run.mcap writes these, and
    Foxglove live's ROS-typed channels serve them."""
    fast = encoded_record(record, names)
    if fast is not None:
        return [fast]
    return [(topic, serializer.cdr(msgtype, fields))
            for topic, msgtype, fields in messages(record, names)]


def encoded_record(record: Any, names: RosNames) -> tuple[str, bytes] | None:
    """The topic and CDR bytes of a record of every cycle (:mod:`seqrun.ros_messages.cdr`:
    the same bytes as rosbags' serializer, a fraction of its time); None for the others."""
    import math

    if isinstance(record, Joints):
        topic = names.joint_states if record.kind == "joint_states" else names.joint_commands
        velocity = [] if record.velocities_deg_s is None else \
            [math.radians(v) for v in record.velocities_deg_s]
        return topic, cdr.joint_state(record.stamp_ns, "", record.names,
                                      [math.radians(v) for v in record.positions_deg],
                                      velocity)
    if isinstance(record, Frames):
        return TF_TOPIC, cdr.tf_message(record.stamp_ns, record.transforms)
    if isinstance(record, EventLine):
        return EVENTS_TOPIC, cdr.string(record.line)
    if isinstance(record, Shapes):
        return MARKERS_TOPIC, cdr.marker_array(record.stamp_ns, names.base_frame,
                                               record.shapes)
    return None


def below_the_loop() -> None:
    """This thread under the control loop: a thread inherits the real-time scheduling of
    the thread that starts it (``seqrun run --rt-priority``: the loop's SCHED_FIFO), and
    the writer must never hold the CPU the loop wants; SCHED_RR priority 1 is the level of
    the process's other threads (seqrun/service/realtime.py)."""
    import os

    try:
        if os.sched_getscheduler(0) == os.SCHED_FIFO:
            os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(1))
    except (OSError, AttributeError):
        pass


class QueuedBagWriter:
    """A run.mcap written by a thread of its own from a bounded queue: handing an item over
    never waits (a full queue drops and counts), a failing disk stops the file, said once
    through ``on_error(text)`` (from that thread). Subclasses say how an item is written
    (:meth:`_write`) and make the bag (``make_bag``)."""

    def __init__(self, folder: Path, make_bag: Callable[[], Any], *, thread_name: str,
                 on_error: Callable[[str], None] | None = None,
                 queue_size: int = QUEUE_SIZE) -> None:
        self.folder = Path(folder)
        self.on_error = on_error
        self.error: str | None = None
        self.path: Path | None = None
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=queue_size)
        self._bag: Any = None
        try:
            self._bag = make_bag()
        except Exception as exc:  # noqa: BLE001 - run.mcap must never stop the run
            self._fail(exc)
        self._thread = threading.Thread(target=self._run, name=thread_name, daemon=True)
        self._closed = False
        if self._bag is not None:
            self._thread.start()

    def _offer(self, item: Any) -> bool:
        """Queue ``item`` without waiting; False when it was dropped (the queue full)."""
        if self._bag is None or self._closed:
            return True
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            return False
        return True

    def _write(self, bag: Any, item: Any) -> None:
        raise NotImplementedError

    def _run(self) -> None:
        below_the_loop()
        bag = self._bag
        assert bag is not None
        while True:
            item = self._queue.get()
            if item is _STOP:
                break
            if self.error is not None:
                continue
            try:
                self._write(bag, item)
            except Exception as exc:  # noqa: BLE001 - a disk error or a bug: stop the file
                self._fail(exc)
                bag.abort()
            time.sleep(0)   # hand the interpreter lock over: a control loop may wait for it
        if self.error is None:
            try:
                self.path = bag.close()
            except Exception as exc:  # noqa: BLE001
                self._fail(exc)

    def _fail(self, exc: BaseException) -> None:
        if self.error is not None:
            return
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        self.error = f"writing {self.folder / MCAP_NAME} failed ({why}); that file stops here"
        if self.on_error is not None:
            try:
                self.on_error(self.error)
            except Exception:  # noqa: BLE001
                pass

    def close(self, timeout: float = 60.0) -> Path | None:
        """Write what is queued, end the file; ``run.mcap``'s path, or None (failed)."""
        if self._closed:
            return self.path
        self._closed = True
        if self._bag is None:
            return None
        self._queue.put(_STOP)
        self._thread.join(timeout)
        if self._thread.is_alive():
            self._fail(TimeoutError(f"still writing after {timeout:g} s"))
        return self.path

    @property
    def counts(self) -> dict[str, int]:
        return dict(self._bag.counts) if self._bag is not None else {}


class McapLog(QueuedBagWriter):
    """``run.mcap`` of one run, fed by the run log (:meth:`put`) and written by a thread of
    its own. ``on_error(text)`` is told once when writing fails (from that thread)."""

    def __init__(self, folder: Path, arm: ArmDescription, *, namespace: str | None = None,
                 distribution: str = DEFAULT_DISTRIBUTION,
                 on_error: Callable[[str], None] | None = None,
                 queue_size: int = QUEUE_SIZE) -> None:
        self.dropped = 0
        self.names = RosNames.of(arm, namespace)
        self.distribution = distribution
        super().__init__(folder, lambda: BagWriter(Path(folder), arm, self.names, distribution),
                         thread_name="seqrun-mcap", on_error=on_error, queue_size=queue_size)

    def put(self, event: Mapping[str, Any]) -> None:
        """Hand one event (an events.jsonl line's dict) over; never waits."""
        if not self._offer(event):
            self.dropped += 1

    def _write(self, bag: BagWriter, item: Mapping[str, Any]) -> None:
        bag.write_event(item)


def write_mcap(folder: Path, events: Iterable[Mapping[str, Any]], arm: ArmDescription, *,
               namespace: str | None = None,
               distribution: str = DEFAULT_DISTRIBUTION) -> tuple[Path, dict[str, int]]:
    """``folder/run.mcap`` from a run's events (events.jsonl's lines, in order); returns
    its path and the message count per topic. Raises on error (nothing half-written is
    left as run.mcap)."""
    bag = BagWriter(Path(folder), arm, RosNames.of(arm, namespace), distribution)
    try:
        for event in events:
            bag.write_event(event)
    except BaseException:
        bag.abort()
        shutil.rmtree(bag.partial, ignore_errors=True)
        raise
    return bag.close(), dict(bag.counts)


def rebuild_mcap(folder: Path, arm: ArmDescription | None = None) -> tuple[Path, dict[str, int]]:
    """``seqrun report RUN_DIR --mcap``: write ``run.mcap`` of a run folder anew from its
    events.jsonl (older runs, or one killed before its run.mcap was ended). The namespace
    and ROS 2 distribution are those the run recorded (report.json ``ros``), else the arm
    file's stem and the frozen seqrun.toml's ``[ros] distribution`` (default Jazzy).
    Raises :class:`seqrun.errors.UserInputError` for a folder that cannot give one."""
    import json

    from seqrun.errors import UserInputError
    from seqrun.runfolder.logfile import read_lines
    from seqrun.runfolder.names import events_path

    folder = Path(folder)
    events_file = events_path(folder)
    if events_file is None:
        raise UserInputError(f"{folder}: no events.jsonl(.gz) (not a run folder, or a run "
                             "refused before it started): nothing to write run.mcap from")
    report: dict[str, Any] = {}
    try:
        loaded = json.loads((folder / "report.json").read_text(encoding="utf-8"))
        report = loaded if isinstance(loaded, dict) else {}
    except (OSError, ValueError):
        pass
    events = []
    for raw in read_lines(events_file):
        try:
            event = json.loads(raw)
        except ValueError:
            continue
        if isinstance(event, dict):
            events.append(event)
    started = next((e for e in events if e.get("type") == "run_started"), None)
    if started is None:
        raise UserInputError(f"{events_file}: no run_started event; nothing to write "
                             "run.mcap from")
    if arm is None:
        from seqrun.arm.description import ArmDescription

        try:
            arm = ArmDescription.model_validate(started.get("arm"))
        except ValueError:
            raise UserInputError(f"{events_file}: the run did not record its arm; give the "
                                 "arm file with --arm FILE") from None
    if "start_epoch_s" not in started:   # an older run: the report's time base
        epoch = report.get("start_epoch_s")
        started["start_epoch_s"] = float(epoch) if isinstance(epoch, (int, float)) else 0.0
    recorded = report.get("ros")
    ros: dict[str, Any] = recorded if isinstance(recorded, dict) else {}
    namespace = ros.get("namespace") or _arm_input_stem(report)
    distribution = ros.get("distribution") or _frozen_distribution(folder)
    result = write_mcap(folder, events, arm, namespace=namespace,
                        distribution=distribution or DEFAULT_DISTRIBUTION)
    return result


def _arm_input_stem(report: Mapping[str, Any]) -> str | None:
    from seqrun.ros_messages.names import ros_name

    for item in report.get("inputs") or ():
        if isinstance(item, dict) and item.get("kind") == "arm" and item.get("file"):
            return ros_name(Path(str(item["file"])).stem)
    return None


def _frozen_distribution(folder: Path) -> str | None:
    """``[ros] distribution`` of the seqrun.toml the run froze into inputs/, if any."""
    import tomllib

    for path in sorted(Path(folder, "inputs").rglob("seqrun.toml")):
        try:
            value = tomllib.loads(path.read_text(encoding="utf-8")).get("ros", {})
        except (OSError, ValueError):
            continue
        distribution = value.get("distribution") if isinstance(value, dict) else None
        if distribution in DISTRIBUTIONS:
            return str(distribution)
    return None
