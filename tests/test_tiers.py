"""The tiers themselves: the fast loop draws a share of each property test's examples, every
other run (CI's) the full count."""

from __future__ import annotations

import pytest
from hypothesis import settings

import tiers


@pytest.fixture
def restore_tier():
    fast, profile = tiers.FAST, settings.get_current_profile_name()
    yield
    tiers.FAST = fast
    settings.load_profile(profile)


@pytest.mark.parametrize("markexpr, env, fast", [
    ("not slow", None, True), ("not  slow", None, True),
    ("", None, False), ("slow", None, False), ("not slow and not browser", None, False),
    ("not slow", "full", False)])
def test_only_the_fast_loop_draws_fewer_examples(restore_tier, monkeypatch, markexpr, env,
                                                 fast):
    if env is None:
        monkeypatch.delenv("SEQRUN_EXAMPLES", raising=False)
    else:
        monkeypatch.setenv("SEQRUN_EXAMPLES", env)
    settings.load_profile("default")
    tiers.configure(markexpr)
    assert tiers.FAST is fast
    assert tiers.examples(400) == (100 if fast else 400)
    assert tiers.examples(20) == (10 if fast else 20)
    # Tests without a count of their own: the fast profile, else the profile left as it was.
    assert settings().max_examples == (25 if fast else settings.get_profile("default").max_examples)
