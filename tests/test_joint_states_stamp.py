"""The stamp of the bag's measured joint_states, as docs/ros2.md says it (issue 44, item 8):
one cycle's answers (within 2 ms) are stamped at the mean of their bus times; answers a
host stall split are stamped at the latest (when the whole reading existed)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from projecttree import ROOT, shipped_arm
from seqrun.execution.streaming import Streaming
from seqrun.ros_messages.from_events import EventTranslator, Joints
from seqrun.ros_messages.values import stamp_ns

EPOCH = 1000.0


def logged_read_t(answered_at: list[float]) -> float | list[float]:
    """``read_t`` as the executor logs it for answers at these run times."""
    run = SimpleNamespace(limits=None, since_start=lambda t: t)
    return Streaming(run).read_t(SimpleNamespace(answered_at=answered_at, t=max(answered_at)))


def joint_states_stamp(read_t: float | list[float]) -> int:
    translator = EventTranslator(shipped_arm())
    translator.translate({"t": 0.0, "type": "run_started", "start_epoch_s": EPOCH})
    records = translator.translate({"t": 2.5, "type": "setpoint", "read_t": read_t,
                                    "plan_t": 2.5, "planned_deg": [0.0] * 7,
                                    "measured_deg": [0.0] * 7})
    [measured] = [r for r in records if isinstance(r, Joints) and r.kind == "joint_states"]
    return measured.stamp_ns


def test_one_cycles_answers_are_stamped_at_their_mean():
    answers = [2.4900, 2.4903, 2.4906, 2.4909, 2.4912, 2.4915, 2.4918]   # 1.8 ms apart
    read_t = logged_read_t(answers)
    assert read_t == pytest.approx(sum(answers) / len(answers), abs=1e-6)
    assert joint_states_stamp(read_t) == stamp_ns(EPOCH + read_t)
    # every joint's own answer within 1 ms of the stamp
    assert max(abs(a - read_t) for a in answers) < 0.001


def test_answers_split_by_a_stall_are_stamped_at_the_latest():
    answers = [2.30, 2.30, 2.30, 2.30, 2.55, 2.55, 2.55]   # a 250 ms stall mid-exchange
    read_t = logged_read_t(answers)
    assert read_t == answers   # one time per joint in events.jsonl
    assert joint_states_stamp(read_t) == stamp_ns(EPOCH + 2.55)


def test_the_docs_say_what_the_code_does():
    text = " ".join((ROOT / "docs" / "ros2.md").read_text(encoding="utf-8").split())
    assert "the **mean** of their acknowledges' bus time stamps" in text
    assert "the **latest** of them" in text
