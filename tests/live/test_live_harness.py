"""The browser tests' simulated clock (``live_harness.py``) without a browser: a stand-in page whose
``sim_time`` moves, restarts with a new episode, or stands still."""

from __future__ import annotations

import pytest
from live_harness import SimClock


class Page:
    def __init__(self):
        self.sim_time = None

    def execute_script(self, script):
        assert "lastState" in script
        return self.sim_time


def test_the_clock_sums_forward_steps_and_counts_a_new_episode_from_zero():
    page = Page()
    clock = SimClock(page)
    assert clock.read() == 0.0  # no frame yet
    for value, total in ((1.0, 0.0), (4.5, 3.5), (4.5, 3.5), (0.5, 4.0), (2.0, 5.5)):
        page.sim_time = value
        assert clock.read() == pytest.approx(total)


def test_a_wait_ends_after_its_simulated_seconds_not_before():
    page = Page()
    page.sim_time = 0.0
    clock = SimClock(page, context=lambda: "server said hello")

    def tick():
        page.sim_time += 1.0
        return page.sim_time >= 5.0

    assert clock.wait(tick, 10, "five seconds", poll=0) is True
    page.sim_time = 0.0
    with pytest.raises(AssertionError, match=r"3 simulated s passed waiting for never\nserver said hello"):
        clock.wait(lambda: bool(setattr(page, "sim_time", page.sim_time + 1.0)), 3, "never", poll=0)


def test_a_clock_that_stands_still_fails_after_the_stall_limit():
    page = Page()
    page.sim_time = 2.0
    clock = SimClock(page)
    with pytest.raises(AssertionError, match="stood still"):
        clock.wait(lambda: False, 10, "a frozen page", stall_s=0.2, poll=0.01)
