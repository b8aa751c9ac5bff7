"""Typed events: every emitted type is a documented record, the hub never waits for a
subscriber, and events.jsonl keeps its shape."""

from __future__ import annotations

import ast
import threading
import time
from pathlib import Path

import pytest

from runfolder import RunFolder
from seqrun.events import (EVENT_TYPES, EventHub, Measurement, StepFinished, Unregistered,
                           events_markdown, make_event)

ROOT = Path(__file__).resolve().parents[1]


def emitted_calls() -> list[tuple[str, str, set[str], bool]]:
    """Every ``*.emit("type", ...)`` in seqrun/: (where, type, keyword names, has **)."""
    calls = []
    for path in sorted((ROOT / "seqrun").rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr == "emit" and node.args
                    and isinstance(node.args[0], ast.Constant)
                    and isinstance(node.args[0].value, str)):
                names = {k.arg for k in node.keywords if k.arg is not None}
                splat = any(k.arg is None for k in node.keywords)
                calls.append((f"{path.relative_to(ROOT)}:{node.lineno}", node.args[0].value,
                              names, splat))
    return calls


def test_the_scan_finds_the_emit_calls():
    types = {t for _, t, _, _ in emitted_calls()}
    assert {"setpoint", "measurement", "fault", "run_finished", "zero_reference"} <= types


def test_every_emitted_type_has_a_typed_record_and_is_documented():
    docs = (ROOT / "docs" / "events.md").read_text(encoding="utf-8")
    for where, type_, names, splat in emitted_calls():
        assert type_ in EVENT_TYPES, f"{where}: event type '{type_}' has no record in events.py"
        assert f"## `{type_}`" in docs, f"{where}: '{type_}' is not in docs/events.md"
        if not splat:  # every keyword of the call site fits the record
            event = make_event(type_, 0.0, {n: None for n in names})
            assert not isinstance(event, Unregistered), (where, type_, names)


def test_docs_events_md_is_generated_from_the_records():
    assert (ROOT / "docs" / "events.md").read_text(encoding="utf-8").strip() == \
        events_markdown().strip(), "regenerate: python -m seqrun.events > docs/events.md"


def test_as_dict_is_the_events_jsonl_shape():
    # Optional fields absent stay absent; open-ended details are top-level keys; the step
    # number goes with the event; derived fields are not written.
    e = make_event("step_finished", 1.5, {"status": "passed", "duration_s": 1.0,
                                          "planned_duration_s": None, "final_error_deg": [0.1],
                                          "step": 3})
    assert isinstance(e, StepFinished) and e.extra == {"final_error_deg": [0.1]}
    assert e.as_dict() == {"t": 1.5, "type": "step_finished", "status": "passed",
                           "duration_s": 1.0, "planned_duration_s": None,
                           "final_error_deg": [0.1], "step": 3}
    m = make_event("measurement", 2.0, {"joints_deg": [1.0], "state": [2]},
                   velocities_deg_s=[0.5], flags={"j1": ("HOME_OK",)}, fault=False)
    assert isinstance(m, Measurement) and m.velocities_deg_s == [0.5]
    assert m.as_dict() == {"t": 2.0, "type": "measurement", "joints_deg": [1.0], "state": [2]}
    assert m["joints_deg"] == [1.0] and m.get("after") is None and "after" not in m
    # A fault keeps step: None (no step: preflight), as before.
    f = make_event("fault", 0.1, {"cause": "bus_error", "module": None, "message": "x",
                                  "step": None, "halt_sent": True, "halt_confirmed": True})
    assert f.as_dict()["step"] is None


def test_a_setpoint_keeps_its_own_time():
    e = make_event("setpoint", 9.0, {"t": 1.25, "plan_t": 0.5, "planned_deg": [0],
                                     "measured_deg": [0], "planned_vel_deg_s": [0],
                                     "state": [0]})
    assert e.t == 1.25 and e.as_dict()["t"] == 1.25 and "t" not in e.extra


def test_publish_never_waits_for_a_slow_subscriber_and_drops_the_oldest():
    hub = EventHub()
    release = threading.Event()
    seen = []

    def slow(event):
        seen.append(event.t)
        release.wait(5)

    listener = hub.add_listener(slow, "slow", maxsize=10)
    fast = hub.subscribe(maxsize=1000)
    t0 = time.perf_counter()
    for k in range(500):
        hub.publish(make_event("pause_requested", float(k), {}))
    elapsed = time.perf_counter() - t0
    release.set()
    listener.close(timeout=5)
    # 500 publishes with a subscriber stuck in its callback: far below one blocked call.
    assert elapsed < 1.0
    assert len(fast) == 500 and fast.dropped == 0
    # The slow one kept the newest 10 (plus the one it was handling), counted the rest.
    assert listener.dropped + len(seen) == 500 and len(seen) <= 11
    assert seen[-10:] == [float(k) for k in range(490, 500)]


def test_a_failing_listener_stops_alone():
    hub = EventHub()

    def broken(event):
        raise RuntimeError("display gone")

    bad = hub.add_listener(broken, "broken")
    good = hub.subscribe()
    hub.publish(make_event("pause_requested", 0.0, {}))
    hub.publish(make_event("run_resumed", 0.1, {}))
    deadline = time.monotonic() + 5
    while bad.error is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert isinstance(bad.error, RuntimeError)
    assert [e.type for e in good.drain()] == ["pause_requested", "run_resumed"]
    assert hub.subscribers == 1


def test_get_times_out_and_close_ends_iteration():
    hub = EventHub()
    sub = hub.subscribe()
    assert sub.get(timeout=0.01) is None
    hub.publish(make_event("pause_requested", 0.0, {}))
    threading.Timer(0.05, sub.close).start()
    assert [e.type for e in sub] == ["pause_requested"]


@pytest.mark.parametrize("bad", [0, -1])
def test_a_queue_holds_at_least_one_event(bad):
    with pytest.raises(ValueError):
        EventHub().subscribe(maxsize=bad)


@pytest.mark.parametrize("faults", [[], ["2:tow_error@3"]])
def test_a_run_emits_only_registered_events(tmp_path, faults):
    """At run time too (the ** call sites the scan cannot see): a whole sequence, with and
    without a fault, through the runner, gives typed records only."""
    from seqrun.arm.description import load_arm
    from seqrun.clock import VirtualClock
    from seqrun.service.connection import open_connection
    from seqrun.service.runner import run_sequence
    from seqrun.sequence.loader import load_sequence
    from seqrun.sim.faults import parse_fault_spec

    loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
    connection = open_connection(force_sim=True, clock=VirtualClock(),
                                 faults=[parse_fault_spec(f) for f in faults])
    seen = []
    try:
        outcome = run_sequence(loaded, load_arm(loaded.arm_path), connection,
                               log_dir=tmp_path / "run", confirm=lambda prompt: True,
                               listeners=[seen.append], html_report=False)
    finally:
        connection.close()
    assert outcome.result.exit_code == (3 if faults else 0)
    assert seen and not [e for e in seen if isinstance(e, Unregistered)]
    types = {e.type for e in seen}
    assert {"run_started", "preflight", "setpoint", "step_finished", "run_finished"} <= types
    if faults:
        assert {"fault", "halt_confirmed"} <= types
    lines = RunFolder(tmp_path / "run").events()
    assert len(lines) == len(seen)
