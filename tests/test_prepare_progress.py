"""A preparation says how far it is (``Planner.report_progress``, docs/running.md "Preparation"):
the messages cross the job's pipe as hostile data (size, rate, types, order, nonce checked; text
made printable) and reach the display with an estimate of the time left."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from earthbench.cli.preparing import PrepareDisplay, duration, status_line
from earthbench.running.harness import build_cases, run_case
from earthbench.running.harness.prepare import PrepareError, PrepareStatus, ensure, estimate, forget, last_recorded
from earthbench.running.harness.protocol import PROGRESS_BURST, PROGRESS_RATE
from earthbench.planner import PrepareProgress
from earthbench.results.records import PlannerRef
from earthbench.results.suite import parse_suite
from earthbench.world import Budget

from helpers import tiny_suite_toml


PLUGIN = str(Path(__file__).parent / "plugins" / "preparing_planners.py")

pytestmark = pytest.mark.usefixtures("forget_test_planners", "prepared_root")


def _steps(statuses: list[PrepareStatus]) -> list[PrepareProgress]:
    """The progress messages the harness accepted (each status repeats the last one between them)."""
    out: list[PrepareProgress] = []
    for s in statuses:
        if s.progress is not None and (not out or s.progress is not out[-1]):
            out.append(s.progress)
    return out


def test_a_preparation_reports_its_steps_and_they_are_shown_with_an_estimate(tmp_path, prepared_root):
    ref = PlannerRef.resolve("t-prepare-reports")
    log: list[str] = []
    statuses: list[PrepareStatus] = []
    assert ensure(ref, Budget(), log=log.append, on_progress=statuses.append) is not None
    what = "\\x1b[2Jstep {} of three"  # one line, the escape written out, not sent to the terminal
    assert [(p.done, p.total, p.what) for p in _steps(statuses)] == [
        (0, 3, what.format(0)), (1, 3, what.format(1)), (2, 3, what.format(2)), (3, 3, "done")]  # 4 of 3 mended
    assert all(a.elapsed_s <= b.elapsed_s for a, b in zip(statuses, statuses[1:]))
    first_step = next(s for s in statuses if s.progress is not None and s.progress.done == 1)
    assert first_step.left_s == pytest.approx(2 * first_step.elapsed_s)  # no earlier preparation: from the steps
    shown = io.StringIO()
    display = PrepareDisplay(shown, live=True)
    for s in statuses:
        display.progress(s)
    display.log(log[-1])
    text = shown.getvalue()
    assert "\x1b[2J" not in text and "t-prepare-reports: 2 of 3 · \\x1b[2Jstep 2 of three · " in text
    assert text.endswith("\r\x1b[K" + f"earthbench: {log[-1]}\n")
    # the next preparation of the planner knows what the last one took (here: an older one's 1000 s)
    older = prepared_root / "t-prepare-reports-older"
    older.mkdir()
    (older / "prepare.json").write_text('{"planner": "t-prepare-reports", "started_at": "9999", "wall_s": 1000.0}')
    assert last_recorded("t-prepare-reports") == 1000.0
    forget(ref)
    log.clear()
    again: list[PrepareStatus] = []
    ensure(ref, Budget(), log=log.append, on_progress=again.append)
    assert "(the last preparation of t-prepare-reports here took 1000 s)" in log[0]
    assert again and all(s.left_s == pytest.approx(1000.0 - s.elapsed_s) for s in again)


def test_a_flood_of_progress_is_read_and_kept_to_ten_a_second(tmp_path):
    statuses: list[PrepareStatus] = []
    ref = PlannerRef.resolve("t-prepare-floods")
    assert ensure(ref, Budget(), on_progress=statuses.append) is not None
    kept = _steps(statuses)
    assert PROGRESS_BURST <= len(kept) <= PROGRESS_BURST + PROGRESS_RATE * (statuses[-1].elapsed_s + 1)


@pytest.mark.parametrize("kind, why", [
    ("types", "malformed progress message"), ("order", "says 4 of 3 steps"), ("huge", "over the limit of 2,048"),
    ("nonce", "does not echo the nonce"),
])
def test_a_malformed_progress_message_ends_the_preparation(kind, why):
    with pytest.raises(PrepareError, match=why):
        ensure(PlannerRef.resolve("t-prepare-bad-progress", {"kind": kind}), Budget(), on_progress=lambda s: None)


def test_a_case_that_sends_progress_ends_as_an_error():
    (case,), _ = build_cases(parse_suite(tiny_suite_toml("progress")), ["t-plan-progress"], plugins=[PLUGIN])
    res = run_case(case, (0,))
    assert res.reason == "error" and "only a preparation reports progress" in res.error


def test_the_estimate_uses_the_last_preparation_until_it_is_outrun_then_the_steps():
    assert estimate(None, 10.0, 100.0) == 90.0
    assert estimate(PrepareProgress(1, 4), 10.0, None) == 30.0
    assert estimate(PrepareProgress(1, 4), 200.0, 100.0) == 600.0
    assert estimate(PrepareProgress(0, 4), 10.0, None) is None and estimate(None, 5.0, None) is None


def test_a_log_gets_a_line_per_step_not_per_second():
    shown = io.StringIO()
    display = PrepareDisplay(shown, live=False)
    display.log("preparing x")
    for k in range(50):  # fifty ticks within a second: no line yet
        display.progress(PrepareStatus("x", PrepareProgress(0, 3, "a"), 0.02 * k, None))
    assert shown.getvalue() == "earthbench: preparing x\n"
    display.printed_at -= 11.0  # eleven seconds later, the next step shows
    display.progress(PrepareStatus("x", PrepareProgress(1, 3, "b"), 11.0, 22.0))
    assert shown.getvalue().splitlines()[-1] == status_line(PrepareStatus("x", PrepareProgress(1, 3, "b"), 11.0, 22.0))
    assert status_line(PrepareStatus("x", None, 75.0, 3725.0)) == "  x: working · 1 min 15 s, about 1 h 2 min left"
    assert (duration(42.4), duration(500), duration(3725)) == ("42 s", "8 min 20 s", "1 h 2 min")


def test_the_live_line_redraws_on_the_terminal_and_escapes_its_text():
    from earthbench.cli._common import PrintableStream

    raw = io.StringIO()
    display = PrepareDisplay(PrintableStream(raw), live=True)  # the streams every command prints through
    display.progress(PrepareStatus("x", PrepareProgress(1, 2, "bell\x07"), 1.0, None))
    display.log("prepared x")
    assert raw.getvalue() == "\r  x: 1 of 2 · bell\\x07 · 1 s\x1b[K\r\x1b[Kearthbench: prepared x\n"
