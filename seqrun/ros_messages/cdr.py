"""CDR (little-endian, ROS 2's serialization) of the messages seqrun writes at every cycle:
``sensor_msgs/JointState``, ``tf2_msgs/TFMessage``, ``std_msgs/String``.

The generic way (rosbags' message objects and serializer) costs about a millisecond per
cycle; these encoders write the same bytes (tests/test_mcap_log.py compares them with
rosbags' own serializer) in a few tens of microseconds, on the run.mcap writer's thread.
Pure: struct packing, no I/O.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any

from seqrun.ros_messages.values import MARKER_TYPES, Shape, Transform, split_stamp

#: The encapsulation header of little-endian plain CDR.
_HEADER = b"\x00\x01\x00\x00"


class _Cdr:
    """A CDR body after the 4-byte header (alignment counts from the body's start)."""

    def __init__(self) -> None:
        self.parts: list[bytes] = [_HEADER]
        self.size = 0

    def _put(self, data: bytes) -> None:
        self.parts.append(data)
        self.size += len(data)

    def align(self, n: int) -> None:
        pad = -self.size % n
        if pad:
            self._put(b"\x00" * pad)

    def u32(self, value: int) -> None:
        self.align(4)
        self._put(struct.pack("<I", value))

    def time(self, ns: int) -> None:
        sec, nanosec = split_stamp(ns)
        self.align(4)
        self._put(struct.pack("<iI", sec, nanosec))

    def string(self, text: str) -> None:
        data = text.encode("utf-8") + b"\x00"
        self.u32(len(data))
        self._put(data)

    def strings(self, texts: Sequence[str]) -> None:
        self.u32(len(texts))
        for text in texts:
            self.string(text)

    def float64s(self, values: Sequence[float]) -> None:
        self.u32(len(values))
        if values:
            self.align(8)
            self._put(struct.pack(f"<{len(values)}d", *values))

    def float64_fixed(self, values: Sequence[float]) -> None:
        self.align(8)
        self._put(struct.pack(f"<{len(values)}d", *values))

    def raw(self, fmt: str, *values: object, align: int = 4) -> None:
        self.align(align)
        self._put(struct.pack("<" + fmt, *values))

    def header(self, ns: int, frame: str) -> None:
        self.time(ns)
        self.string(frame)

    def bytes(self) -> bytes:
        return b"".join(self.parts)


def _joint_state_template(frame: str, names: tuple[str, ...], counts: tuple[int, int, int]
                          ) -> tuple[bytes, int, tuple[int, int, int]]:
    """A JointState's bytes with zero values, the stamp's offset and each array's."""
    cdr = _Cdr()
    cdr.header(0, frame)
    cdr.strings(names)
    offsets = []
    for n in counts:
        cdr.u32(n)
        if n:
            cdr.align(8)
        offsets.append(4 + cdr.size)
        if n:
            cdr.raw(f"{n}d", *([0.0] * n), align=8)
    return cdr.bytes(), 4, (offsets[0], offsets[1], offsets[2])


def joint_state(stamp_ns: int, frame: str, names: Sequence[str], position: Sequence[float],
                velocity: Sequence[float] = (), effort: Sequence[float] = ()) -> bytes:
    """``sensor_msgs/msg/JointState`` (radians, rad/s, as given). The layout of a set of
    names is made once; each message is that template with its numbers put in."""
    key = (frame, tuple(names), (len(position), len(velocity), len(effort)))
    template = _TEMPLATES.get(key)
    if template is None:
        template = _TEMPLATES[key] = _joint_state_template(*key)
    data, stamp_at, offsets = template
    out = bytearray(data)
    struct.pack_into("<iI", out, stamp_at, *split_stamp(stamp_ns))
    for at, values in zip(offsets, (position, velocity, effort)):
        if values:
            struct.pack_into(f"<{len(values)}d", out, at, *values)
    return bytes(out)


def _tf_template(frames: tuple[tuple[str, str], ...]) -> tuple[bytes, list[int], list[int]]:
    cdr = _Cdr()
    cdr.u32(len(frames))
    stamps, values = [], []
    for parent, child in frames:
        cdr.align(4)
        stamps.append(4 + cdr.size)
        cdr.header(0, parent)
        cdr.string(child)
        cdr.align(8)
        values.append(4 + cdr.size)
        cdr.float64_fixed([0.0] * 7)
    return cdr.bytes(), stamps, values


def tf_message(stamp_ns: int, transforms: Sequence[Transform]) -> bytes:
    """``tf2_msgs/msg/TFMessage``: every transform stamped ``stamp_ns`` (a template per
    chain of frames, like :func:`joint_state`)."""
    key = tuple((tf.parent, tf.child) for tf in transforms)
    template = _TEMPLATES.get(key)
    if template is None:
        template = _TEMPLATES[key] = _tf_template(key)
    data, stamps, values = template
    out = bytearray(data)
    sec, nanosec = split_stamp(stamp_ns)
    for stamp_at, value_at, tf in zip(stamps, values, transforms):
        struct.pack_into("<iI", out, stamp_at, sec, nanosec)
        struct.pack_into("<7d", out, value_at, *tf.translation_m, *tf.rotation_xyzw)
    return bytes(out)


#: Layouts made so far (a handful per process: one per arm and message kind).
_TEMPLATES: dict[Any, Any] = {}


def marker_array(stamp_ns: int, frame: str, shapes: Sequence[Shape]) -> bytes:
    """``visualization_msgs/msg/MarkerArray`` of ``shapes`` (ADD, forever, in ``frame``):
    the fields of Humble's, Jazzy's and Kilted's Marker alike (textures and meshes empty)."""
    cdr = _Cdr()
    cdr.u32(len(shapes))
    for shape in shapes:
        cdr.header(stamp_ns, frame)
        cdr.string(shape.namespace)
        cdr.raw("iii", shape.id, MARKER_TYPES[shape.kind], 0)        # id, type, action ADD
        cdr.float64_fixed((*shape.position_m, *shape.rotation_xyzw, *shape.scale_m))
        cdr.raw("4f", *shape.rgba)
        cdr.raw("iI", 0, 0)                                            # lifetime: forever
        cdr.raw("?", False, align=1)                                   # frame_locked
        cdr.u32(0)                                                     # points
        cdr.u32(0)                                                     # colors
        cdr.string("")                                                 # texture_resource
        cdr.header(0, "")                                              # texture: header,
        cdr.string("")                                                 # format,
        cdr.u32(0)                                                     # data
        cdr.u32(0)                                                     # uv_coordinates
        cdr.string(shape.label)                                        # text
        cdr.string("")                                                 # mesh_resource
        cdr.string("")                                                 # mesh_file: filename,
        cdr.u32(0)                                                     # data
        cdr.raw("?", False, align=1)                                   # mesh_use_embedded_materials
    return cdr.bytes()


def string(text: str) -> bytes:
    """``std_msgs/msg/String``."""
    cdr = _Cdr()
    cdr.string(text)
    return cdr.bytes()
