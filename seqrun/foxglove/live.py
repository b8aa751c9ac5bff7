"""The session's data live on a Foxglove WebSocket server, and its services.

Channels, ``types="foxglove"`` (the default; the same data as run.mcap,
:mod:`seqrun.ros_messages`, in Foxglove's own schemas, protobuf): ``/<arm>/joint_states`` and ``/<arm>/joint_commands`` (foxglove.JointStates,
radians), ``/tf`` (foxglove.FrameTransforms: every link of seqrun's FK),
``/seqrun/scene`` (foxglove.SceneUpdate: link capsules, guards, obstacles),
``/seqrun/log`` (foxglove.Log: one line per event) and ``/seqrun/events`` (JSON: the
events.jsonl line of every event).

``types="ros"`` (``--foxglove-types ros``): run.mcap's own channels instead, the same topics,
ROS 2 types, ``ros2msg`` schemas and CDR bytes (:mod:`.ros_channels`), so that a layout made
on a recorded run.mcap works live.

Services (JSON requests and responses): ``/seqrun/stop`` is always accepted, like the
console's STOP, whatever its body: the Halt broadcast goes out at once, then it is confirmed,
and the answer says so. Everything else that commands the arm (``/seqrun/reset``: Reset and
the arm file's limits written, as the console's Arm; ``/seqrun/home``,
``/seqrun/move_to_pose``) goes through the session's control desk
(:mod:`seqrun.service.control`), as in the console: a client takes control with
``/seqrun/take_control`` (it must be subscribed to a topic: its subscriptions are how the
server sees it connected) and gets a secret in the answer's ``token``, which every command
carries (``{"token": ...}``); held by another client, control is taken only with
``take_over`` (that client's motion is stopped first, and it is told). A holder that
releases control, or leaves (its last subscription ends: it closed the connection), ends
its motion with a controlled stop.

A campaign's run of several arms (``arms``: one server for every arm): each arm's channels
under its arm id, as the campaign's run.mcap names them (:mod:`seqrun.service.arms_mcap`),
in either ``types``: ``/<id>/joint_states``, ``/<id>/joint_commands`` (``/<id>/planned``
with "ros"), one ``/tf`` for every arm (frames ``<id>/base``, ``<id>/j1`` ...),
``/tf_static`` (``facility`` -> ``<id>/base``: each arm's base, seqrun.toml ``[arms.ID]
base``), ``/<id>/events``, and ``/<id>/scene`` and ``/<id>/log`` ("foxglove") or
``/<id>/markers`` ("ros"; a campaign's run.mcap has no ``/robot_description``).
``/seqrun/stop`` halts every arm at once; each arm's other services are under its id
(``/<id>/seqrun/take_control`` ...), each going through that arm's session and its control
desk as one arm's do.

Who may connect: the console's Host and Origin rules (:mod:`seqrun.foxglove.gate`), so a
web page of another site open in the operator's browser reaches nothing.
"""

from __future__ import annotations

import functools
import json
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from seqrun.errors import Refused, SeqrunError
from seqrun.events import Event, Measurement
from seqrun.foxglove.gate import Gate, inner_host
from seqrun.ros_messages.from_events import (EventLine, EventTranslator, Frames, Joints,
                                             Record, Shapes)
from seqrun.ros_messages.names import EVENTS_TOPIC, MARKERS_TOPIC, TF_TOPIC, RosNames
from seqrun.ros_messages.values import Shape, static_shapes
from seqrun.service.control import Client
from seqrun.service.mcap_log import ROBOT_DESCRIPTION_TOPIC

if TYPE_CHECKING:
    from foxglove.websocket import ServerListener

    from seqrun.foxglove.ros_channels import RosChannels

    from seqrun.arm.description import ArmDescription

LOCALHOST = "127.0.0.1"
SCENE_TOPIC = "/seqrun/scene"
LOG_TOPIC = "/seqrun/log"
#: Events waiting for this face; beyond this the oldest go (counted by the subscription).
QUEUE_SIZE = 2000
#: What the live channels carry: Foxglove's own schemas, or run.mcap's ROS 2 types.
TYPES = ("foxglove", "ros")
#: Foxglove's own: what every Foxglove and Lichtblick panel reads without a converter,
#: and what this face served before ``ros`` existed.
DEFAULT_TYPES = "foxglove"


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class StopBody(_Body):
    reason: str | None = Field(None, max_length=200, description="Said in the Halt's events.")


class TakeControlBody(_Body):
    name: str | None = Field(None, min_length=1, max_length=80,
                             description="The name the other clients see.")
    take_over: bool = Field(False, description="From the client that holds control (its "
                                               "motion is stopped first; it is told).")


Token = Field(min_length=1, max_length=100,
              description="The secret /seqrun/take_control answered with.")


class CommandBody(_Body):
    token: str = Token


class PoseBody(_Body):
    token: str = Token
    name: str = Field(min_length=1, max_length=200, description="A pose of the campaign.")
    velocity_scale: float | None = Field(None, gt=0, le=1)


#: name -> (request model, needs control, what it does)
SERVICES: dict[str, tuple[type[_Body], bool, str]] = {
    "/seqrun/stop": (StopBody, False, "STOP: Halt broadcast at once, then confirmed"),
    "/seqrun/take_control": (TakeControlBody, False, "take control: the answer's token is "
                                                     "the secret every command carries"),
    "/seqrun/release_control": (CommandBody, True, "give control up"),
    "/seqrun/reset": (CommandBody, True, "reset every module and write the arm file's "
                                         "limits (the console's Arm), confirmed"),
    "/seqrun/home": (CommandBody, True, "home every module, confirmed"),
    "/seqrun/move_to_pose": (PoseBody, True, "move to a named pose (validated, planned)"),
}


def _schema(name: str, model: type[BaseModel] | None) -> Any:
    import foxglove

    data = json.dumps(model.model_json_schema() if model is not None else
                      {"type": "object"}).encode()
    return foxglove.MessageSchema(encoding="json", schema=foxglove.Schema(
        name=name, encoding="jsonschema", data=data))


@dataclass(frozen=True)
class LiveArm:
    """One arm of a campaign served by one Foxglove server: its session, its arm (with its
    zero applied) and its base in the campaign's facility frame (4x4, mm; seqrun.toml
    ``[arms.ID] base``)."""

    session: Any
    arm: ArmDescription
    base: Any


class _Feed:
    """One arm's side of the server: its topic names, its translator, its channels and its
    session's events. ``arm_id`` None: the one arm of a run of one (its topics as one arm's
    run.mcap names them); else an arm of a campaign (its topics under its arm id, as the
    campaign's run.mcap names them: :mod:`seqrun.service.arms_mcap`)."""

    def __init__(self, arm_id: str | None, session: Any, arm: ArmDescription,
                 names: RosNames, base: Any = None) -> None:
        self.arm_id, self.session, self.arm, self.names, self.base = (arm_id, session, arm,
                                                                      names, base)
        self.translator = EventTranslator(arm, names, live=True)
        self.ros: RosChannels | None = None
        self.last_capsules: list[Shape] = []
        own = "/seqrun" if arm_id is None else f"/{names.namespace}"
        self.scene_topic = f"{own}/scene"
        self.log_topic = f"{own}/log"
        self.events_topic = f"{own}/events"
        self.log_name = "seqrun" if arm_id is None else f"seqrun/{arm_id}"
        #: Where its services are: ``/seqrun/...`` for one arm, ``/<id>/seqrun/...``.
        self.service_prefix = "" if arm_id is None else f"/{names.namespace}"
        self.subscription: Any = None

    @property
    def markers_topic(self) -> str:
        return MARKERS_TOPIC if self.arm_id is None else f"/{self.names.namespace}/markers"

    def foxglove_channels(self, ctx: Any) -> tuple[Any, ...]:
        """Its channels in Foxglove's own schemas (``/tf`` is the server's, shared)."""
        import foxglove
        from foxglove.channels import JointStatesChannel, LogChannel, SceneUpdateChannel

        self.joint_states = JointStatesChannel(self.names.joint_states, context=ctx)
        self.joint_commands = JointStatesChannel(self.names.joint_commands, context=ctx)
        self.scene = SceneUpdateChannel(self.scene_topic, context=ctx)
        self.log = LogChannel(self.log_topic, context=ctx)
        self.events = foxglove.Channel(self.events_topic, schema={"type": "object"},
                                       context=ctx)
        return (self.joint_states, self.joint_commands, self.scene, self.log, self.events)


class FoxgloveLive:
    """A Foxglove WebSocket server on ``host:port`` (0: a free port) for ``session`` (one
    arm: ``arm``), or for every arm of a campaign's run (``arms``: arm id -> :class:`LiveArm`;
    each arm's channels and services under its arm id, see the module doc)."""

    def __init__(self, session: Any = None, arm: ArmDescription | None = None, *,
                 arms: Mapping[str, LiveArm] | None = None, host: str = LOCALHOST,
                 port: int = 8766, namespace: str | None = None, name: str = "seqrun",
                 types: str = DEFAULT_TYPES, distribution: str | None = None) -> None:
        """``types``: "foxglove" or "ros" (:data:`TYPES`); ``distribution``: the ROS 2
        distribution of the "ros" channels' definitions (default the session's campaign's,
        as its run.mcap)."""
        import foxglove
        from foxglove.websocket import Capability

        from seqrun.service.arms_mcap import arm_namespace
        from seqrun.service.mcap_log import RosSerializer, distribution_of

        if types not in TYPES:
            raise ValueError(f"unknown Foxglove channel types {types!r} "
                             f"(one of {', '.join(TYPES)})")
        if arms is None and arm is not None:
            self.feeds = [_Feed(None, session, arm, RosNames.of(arm, namespace))]
        elif arms and arm is None:
            self.feeds = [_Feed(a, one.session, one.arm,
                                RosNames.of(one.arm, arm_namespace(a)), one.base)
                          for a, one in arms.items()]
        else:
            raise ValueError("serve one arm (session and arm) or the arms of a campaign")
        self.types = types
        first = self.feeds[0]
        # one arm's server as it always was: its session, arm, names and translator
        self.session, self.arm, self.names, self.translator = (
            first.session, first.arm, first.names, first.translator)
        self.campaign = arms is not None
        self._lock = threading.Lock()          # the translators: one event at a time
        self._subscribed: dict[int, set[int]] = {}
        self._joined: dict[int, set[int]] = {}   # client -> the feeds whose desk it joined
        self.context = ctx = foxglove.Context()
        self.ros: RosChannels | None = None
        self.tf_static: Any = None
        channels: list[Any] = []
        if types == "ros":
            from seqrun.foxglove.ros_channels import RosChannels, ros_channel
            from seqrun.ros_messages.ros_fields import TF_MESSAGE
            from seqrun.service.arms_mcap import TF_STATIC_TOPIC, arm_renames

            serializer = RosSerializer(distribution or distribution_of(
                getattr(first.session, "project", None)))
            shared: dict[str, Any] = {}
            for feed in self.feeds:
                feed.ros = RosChannels(
                    ctx, feed.arm, feed.names, serializer.distribution, shared=shared,
                    serializer=serializer,
                    rename=None if feed.arm_id is None else arm_renames(feed.names))
                channels += feed.ros.own
            channels += shared.values()
            self.ros = first.ros
            if self.campaign:
                self.tf_static = ros_channel(ctx, serializer, TF_STATIC_TOPIC, TF_MESSAGE)
        else:
            from foxglove.channels import FrameTransformsChannel

            for feed in self.feeds:
                channels += feed.foxglove_channels(ctx)
            self.tf = FrameTransformsChannel(TF_TOPIC, context=ctx)
            channels.append(self.tf)
            if self.campaign:
                from seqrun.service.arms_mcap import TF_STATIC_TOPIC

                self.tf_static = FrameTransformsChannel(TF_STATIC_TOPIC, context=ctx)
        if self.tf_static is not None:
            channels.append(self.tf_static)
        self._channels: tuple[Any, ...] = tuple(channels)
        services = [foxglove.Service(
            f"{feed.service_prefix}{service}", schema=foxglove.ServiceSchema(
                f"seqrun{service.removeprefix('/seqrun')}",
                request=_schema(model.__name__, model), response=_schema("Answer", None)),
            handler=self._handler(service, feed))
            for feed in self.feeds for service, (model, _, _) in SERVICES.items()
            if not (service == "/seqrun/stop" and feed.arm_id is not None)]
        if self.campaign:   # STOP: every arm at once
            services.append(foxglove.Service("/seqrun/stop", schema=foxglove.ServiceSchema(
                "seqrun/stop", request=_schema(StopBody.__name__, StopBody),
                response=_schema("Answer", None)), handler=self._handler("/seqrun/stop")))

        def start(inner: str) -> Any:
            return foxglove.start_server(
                name=name, host=inner, port=0, context=ctx, services=services,
                capabilities=[Capability.Services], supported_encodings=["json"],
                server_listener=cast("ServerListener", _Listener(self)))

        inner = inner_host()
        try:  # the SDK behind the gate, where no page finds it
            self.server = start(inner)
        except Exception:  # noqa: BLE001 - a host with 127.0.0.1 only: the gate still guards
            inner = LOCALHOST
            self.server = start(inner)
        try:
            self.gate = Gate(host, port, (inner, self.server.port))
        except OSError:
            self.server.stop()
            raise
        self.port = self.gate.port
        for feed in self.feeds:
            who = "foxglove" if feed.arm_id is None else f"foxglove {feed.arm_id}"
            feed.subscription = feed.session.events.add_listener(
                functools.partial(self._on_event, feed), who, maxsize=QUEUE_SIZE)
        self.subscription = first.subscription

    @property
    def url(self) -> str:
        return f"ws://{LOCALHOST}:{self.port}"

    # -- data ----------------------------------------------------------------------------
    def _watched(self) -> bool:
        return any(channel.has_sinks() for channel in self._channels)

    def _on_event(self, feed: _Feed, event: Event) -> None:
        if not self._watched():
            return
        data = event.as_dict()
        if isinstance(event, Measurement) and event.velocities_deg_s is not None:
            data["velocities_deg_s"] = list(event.velocities_deg_s)
        with self._lock:
            records = feed.translator.translate(data)
        for record in records:
            self.publish(record, feed)

    def publish(self, record: Record, feed: _Feed | None = None) -> None:
        """``record`` of ``feed``'s arm (default the first) on its channels."""
        feed = feed or self.feeds[0]
        if isinstance(record, Shapes) and any(s.namespace == "capsules" for s in record.shapes):
            feed.last_capsules = [s for s in record.shapes if s.namespace == "capsules"]
        if feed.ros is not None:
            feed.ros.publish(record)
            return
        from foxglove.messages import JointState, JointStates, Log, LogLevel, SceneUpdate
        import math

        if isinstance(record, Joints):
            velocities = record.velocities_deg_s or (None,) * len(record.names)
            message = JointStates(timestamp=_timestamp(record.stamp_ns), joints=[
                JointState(name=n, position=math.radians(p),
                           velocity=None if v is None else math.radians(v))
                for n, p, v in zip(record.names, record.positions_deg, velocities)])
            channel = (feed.joint_states if record.kind == "joint_states"
                       else feed.joint_commands)
            channel.log(message, log_time=record.log_ns)
        elif isinstance(record, Frames):
            self.tf.log(_frame_transforms(record.transforms, record.stamp_ns),
                        log_time=record.log_ns)
        elif isinstance(record, Shapes):
            feed.scene.log(SceneUpdate(entities=self._entities(feed, record.shapes,
                                                               record.stamp_ns)),
                           log_time=record.log_ns)
        elif isinstance(record, EventLine):
            level = {"error": LogLevel.Error, "warning": LogLevel.Warning}.get(
                record.level, LogLevel.Info)
            feed.log.log(Log(timestamp=_timestamp(record.stamp_ns), level=level,
                             message=record.text, name=feed.log_name), log_time=record.log_ns)
            feed.events.log(json.loads(record.line), log_time=record.log_ns)

    def _publish_bases(self, log_ns: int) -> None:
        """``/tf_static`` of a campaign: each arm's base in the facility frame (as its
        run.mcap has it once, at the start; live, each new subscriber gets it at once)."""
        from seqrun.service.arms_mcap import facility_transform

        transforms = [facility_transform(f.names.base_frame, f.base) for f in self.feeds]
        if self.ros is not None:
            from seqrun.ros_messages import cdr

            self.tf_static.log(cdr.tf_message(log_ns, transforms), log_time=log_ns)
        else:
            self.tf_static.log(_frame_transforms(transforms, log_ns), log_time=log_ns)

    def _entities(self, feed: _Feed, shapes: list[Shape] | tuple[Shape, ...],
                  ns: int) -> list[Any]:
        """One scene entity per capsule, guard and obstacle (its primitives together)."""
        from foxglove.messages import (Color, CubePrimitive, CylinderPrimitive, Pose,
                                       Quaternion, SceneEntity, SpherePrimitive, Vector3)

        groups: dict[tuple[str, str], list[Shape]] = {}
        for shape in shapes:
            groups.setdefault((shape.namespace, shape.label), []).append(shape)
        entities = []
        for (namespace, label), members in groups.items():
            kinds: dict[str, list[Any]] = {"cube": [], "sphere": [], "cylinder": []}
            for s in members:
                pose = Pose(position=Vector3(x=s.position_m[0], y=s.position_m[1],
                                             z=s.position_m[2]),
                            orientation=Quaternion(x=s.rotation_xyzw[0], y=s.rotation_xyzw[1],
                                                   z=s.rotation_xyzw[2], w=s.rotation_xyzw[3]))
                size = Vector3(x=s.scale_m[0], y=s.scale_m[1], z=s.scale_m[2])
                color = Color(r=s.rgba[0], g=s.rgba[1], b=s.rgba[2], a=s.rgba[3])
                primitive = {"cube": CubePrimitive, "sphere": SpherePrimitive,
                             "cylinder": CylinderPrimitive}[s.kind]
                kinds[s.kind].append(primitive(pose=pose, size=size, color=color))
            entities.append(SceneEntity(
                timestamp=_timestamp(ns), frame_id=feed.names.base_frame,
                id=f"{namespace}/{label}", cubes=kinds["cube"], spheres=kinds["sphere"],
                cylinders=kinds["cylinder"]))
        return entities

    def _on_subscribe(self, client_id: int, topic: str) -> None:
        with self._lock:
            self._subscribed.setdefault(client_id, set()).add(hash(topic))
        # a new viewer sees the scene (and the robot, the arms' bases) at once, not at the
        # next step
        import time

        from seqrun.ros_messages.values import stamp_ns
        from seqrun.service.arms_mcap import TF_STATIC_TOPIC

        now = stamp_ns(time.time())
        if topic == TF_STATIC_TOPIC and self.tf_static is not None:
            self._publish_bases(now)
        for feed in self.feeds:
            scene = feed.markers_topic if feed.ros is not None else feed.scene_topic
            if topic == scene:
                self.publish(Shapes(now, now, tuple(static_shapes(feed.arm) +
                                                    feed.last_capsules)), feed)
            elif topic == ROBOT_DESCRIPTION_TOPIC and feed.ros is not None:
                feed.ros.describe(now)

    def _on_unsubscribe(self, client_id: int, topic: str) -> None:
        with self._lock:
            topics = self._subscribed.get(client_id, set())
            topics.discard(hash(topic))
            gone = not topics
            if gone:
                self._subscribed.pop(client_id, None)
            joined = self._joined.pop(client_id, set()) if gone else set()
        for index in sorted(joined):   # it left: its motion ends, control is freed
            # (the controlled stop waits for the arm: never on the server's own thread)
            threading.Thread(target=self.feeds[index].session.control.leave,
                             args=(_client_id(client_id),),
                             name="foxglove client left", daemon=True).start()

    # -- services ------------------------------------------------------------------------
    def _handler(self, service: str, feed: _Feed | None = None) -> Callable[[Any], bytes]:
        """``feed``: the arm whose service it is (None: ``/seqrun/stop``, every arm)."""
        model, needs_control, what = SERVICES[service]

        def handle(request: Any) -> bytes:
            if service == "/seqrun/stop":   # before the body is read: a bad body still stops
                answer = self._halt(f"STOP (Foxglove client {request.client_id})")
                try:
                    body = _parse(StopBody, request)
                    if body.reason:
                        answer["reason"] = body.reason
                except ValueError as exc:
                    answer["note"] = f"the arm was halted; the request was refused: {exc}"
                return json.dumps(answer).encode()
            assert feed is not None
            body = _parse(model, request)
            if service == "/seqrun/take_control":
                return json.dumps(self._take(feed, body, request.client_id)).encode()
            if not needs_control:
                raise ValueError(f"unknown service {service}")
            holder = feed.session.control.require(body.token, what)
            return json.dumps(self._command(feed, service, body, holder)).encode()

        return handle

    def _halt(self, reason: str) -> dict[str, Any]:
        """STOP: one arm's Halt (its answer), or every arm's at once (their answers under
        ``arms``, each Halt sent without waiting for another's confirmation)."""
        if not self.campaign:
            return cast("dict[str, Any]", self.session.halt_dict(reason))
        answers: dict[str, Any] = {}

        def halt(feed: _Feed) -> None:
            try:
                answers[str(feed.arm_id)] = feed.session.halt_dict(reason)
            except Exception as exc:  # noqa: BLE001 - said in the answer, the others halt
                answers[str(feed.arm_id)] = {"error": f"{type(exc).__name__}: {exc}"}

        threads = [threading.Thread(target=halt, args=(feed,), daemon=True,
                                    name=f"foxglove STOP {feed.arm_id}") for feed in self.feeds]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        return {"arms": {str(f.arm_id): answers.get(str(f.arm_id)) for f in self.feeds}}

    def _take(self, feed: _Feed, body: TakeControlBody, client: int) -> dict[str, Any]:
        """``/seqrun/take_control``: the answer (with the secret) goes to this client only."""
        control = feed.session.control
        cid = _client_id(client)
        with self._lock:
            connected = client in self._subscribed
        if not connected:
            raise Refused(f"take control: subscribe to a topic first ({feed.events_topic}, "
                          "say): control lasts while this client stays subscribed, and its "
                          "motion stops when it leaves")
        if control.client(cid) is None:
            control.join(cid, f"{body.name or 'Foxglove client'} ({cid})", "foxglove")
            with self._lock:
                self._joined.setdefault(client, set()).add(self.feeds.index(feed))
        return cast("dict[str, Any]", control.take(cid, take_over=body.take_over).as_dict())

    def _command(self, feed: _Feed, service: str, body: Any,
                 holder: Client) -> dict[str, Any]:
        session = feed.session
        if service == "/seqrun/release_control":
            return cast("dict[str, Any]", session.control.release(body.token).as_dict())
        if service == "/seqrun/reset":   # Reset and the limits: the console's Arm
            return _activity_result(session.arm_up())
        if service == "/seqrun/home":
            return _activity_result(session.home())
        if service == "/seqrun/move_to_pose":
            session.move_to_pose(body.name, velocity_scale=body.velocity_scale,
                                 by=holder.name)
            return {"started": True, "pose": body.name}
        raise ValueError(f"unknown service {service}")

    # -- the end -------------------------------------------------------------------------
    def close(self) -> None:
        for feed in self.feeds:
            feed.subscription.close(timeout=1.0)
        self.gate.close()
        with self._lock:
            joined, self._joined = self._joined, {}
        for client, feeds in joined.items():
            for index in feeds:
                self.feeds[index].session.control.leave(_client_id(client))
        self.server.stop()


def _frame_transforms(transforms: Any, stamp_ns: int) -> Any:
    """tf transforms (:class:`~seqrun.ros_messages.values.Transform`) as Foxglove's
    FrameTransforms."""
    from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Vector3

    stamp = _timestamp(stamp_ns)
    return FrameTransforms(transforms=[
        FrameTransform(timestamp=stamp, parent_frame_id=t.parent, child_frame_id=t.child,
                       translation=Vector3(x=t.translation_m[0], y=t.translation_m[1],
                                           z=t.translation_m[2]),
                       rotation=Quaternion(x=t.rotation_xyzw[0], y=t.rotation_xyzw[1],
                                           z=t.rotation_xyzw[2], w=t.rotation_xyzw[3]))
        for t in transforms])


def _timestamp(ns: int) -> Any:
    from foxglove.messages import Timestamp

    return _stamp(Timestamp, ns)


def _stamp(timestamp: Any, ns: int) -> Any:
    return timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def _client_id(client: int) -> str:
    return f"foxglove-{client}"


def _parse(model: type[_Body], request: Any) -> Any:
    """The request's JSON as ``model`` (strict); ValueError in one line otherwise."""
    if request.encoding != "json":
        raise ValueError(f"requests are JSON, not {request.encoding!r}")
    payload = bytes(request.payload)
    try:
        data = json.loads(payload) if payload.strip() else {}
    except (ValueError, RecursionError) as exc:
        raise ValueError(f"not JSON: {exc}") from None
    if not isinstance(data, dict):
        raise ValueError("the request must be a JSON object")
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "request"
        raise ValueError(f"{where}: {first['msg']}") from None


def _activity_result(result: Any) -> dict[str, Any]:
    """A confirmed command's answer; one that did not succeed is a failure in one line."""
    if not result.ok:
        raise SeqrunError(f"{result.kind} {result.status}: {result.message}")
    return {key: (str(value) if value is not None and not isinstance(
        value, (bool, int, float, str)) else value)
        for key, value in result.as_dict().items()}


class _Listener:
    """foxglove-sdk's server listener: who subscribes to what (a client whose last
    subscription ends has left)."""

    def __init__(self, live: FoxgloveLive) -> None:
        self.live = live

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self.live._on_subscribe(client.id, channel.topic)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        self.live._on_unsubscribe(client.id, channel.topic)


def serve(session: Any, arm: ArmDescription | None, port: int,
          say: Callable[[str], None] | None = None, *,
          types: str = DEFAULT_TYPES, arms: Mapping[str, LiveArm] | None = None
          ) -> FoxgloveLive:
    """Start serving ``session`` (``seqrun run``/``console --foxglove``, ``types`` from
    ``--foxglove-types``), or every arm of a campaign's run (``arms``, ``session`` and
    ``arm`` None); says the URL."""
    live = FoxgloveLive(session, arm, arms=arms, port=port, types=types)
    if say is not None:
        kind = ("run.mcap's ROS 2 types" if types == "ros" else "Foxglove's schemas")
        which = "" if arms is None else (
            f"; arms {', '.join(arms)}: each arm's topics and services under /<arm id>/")
        say(f"Foxglove live on {live.url} ({kind}{which}; open it in Foxglove: Open "
            "connection -> Foxglove WebSocket); STOP: /seqrun/stop")
    return live


__all__ = ["DEFAULT_TYPES", "FoxgloveLive", "LiveArm", "SERVICES", "TYPES", "serve"]
