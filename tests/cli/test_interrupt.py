"""fahv.interrupt: a stop requested inside a deferred section is raised at its end."""

import threading

import pytest

from fahv import interrupt


def test_a_stop_outside_a_section_is_raised_at_once():
    with pytest.raises(KeyboardInterrupt):
        interrupt.request()


def test_a_stop_inside_nested_sections_is_raised_when_the_outermost_ends():
    done = []
    with pytest.raises(KeyboardInterrupt):
        with interrupt.deferred():
            with interrupt.deferred():
                interrupt.request()
                done.append("inner body")
            done.append("outer body")
        done.append("after")  # never reached
    assert done == ["inner body", "outer body"]
    with interrupt.deferred():  # nothing left pending
        pass


def test_a_failing_section_keeps_its_own_error_and_clear_forgets_the_stop():
    with pytest.raises(ValueError, match="disk full"), interrupt.deferred():
        interrupt.request()
        raise ValueError("disk full")
    with pytest.raises(KeyboardInterrupt), interrupt.deferred():
        pass  # the stop is still pending: raised at the next section's end
    with pytest.raises(ValueError), interrupt.deferred():
        interrupt.request()
        raise ValueError
    interrupt.clear()
    with interrupt.deferred():
        pass


def test_sections_of_other_threads_defer_nothing():
    seen = []

    def worker():
        with interrupt.deferred():
            try:
                interrupt.request()
            except KeyboardInterrupt:
                seen.append("raised at once")

    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert seen == ["raised at once"]
