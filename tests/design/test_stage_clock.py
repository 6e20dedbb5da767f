"""The design's progress lines: a line per period whatever the stage does, and the time
left from the stage times of the last design of the same file."""

import time

from fahv.design.stage_clock import StageClock


def test_a_silent_stage_still_gets_its_progress_lines():
    lines = []
    with StageClock(None, lines.append, period_s=0.05) as clock:
        clock.stage("closure")
        time.sleep(0.32)  # one LMI: no loop to put a bar on
    assert 4 <= len(lines) <= 7, lines
    assert all(line.startswith("design: closure, ") for line in lines)
    assert "no estimate (no earlier design of this file was timed)" in lines[0]
    assert list(clock.times) == ["closure"] and 0.3 <= clock.times["closure"] <= 0.5


def test_the_time_left_comes_from_the_last_designs_stage_times():
    previous = {"model": 5.0, "closure": 300.0, "onset": 200.0, "laws": 20.0}
    clock = StageClock(previous, lambda line: None, period_s=60.0)
    clock.stage("closure")
    clock.t_stage -= 100.0  # 100 s into the closure: 200 s of it left, then 220 s
    assert abs(clock.left() - 420.0) < 1.0
    assert "about 7.0 min left (the last design's stage times)" in clock.line()
    clock.t_stage -= 250.0  # longer than last time: the stage's part is 0, not negative
    assert abs(clock.left() - 220.0) < 1.0
    clock.stage("a stage the last design did not have")
    assert clock.left() is None
    times = clock.close()
    assert times["closure"] >= 350.0 and set(times) == {
        "closure",
        "a stage the last design did not have",
    }
