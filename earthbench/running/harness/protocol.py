"""The pipe protocol between the harness and a fenced job, as the harness reads it.

A job's bootstrap (:mod:`.child`) writes one JSON object per line on its message pipe:
``ready``; then, for each input it was handed, either a ``step`` (closed loop), ``progress``
(a preparation that says how far it is) or one ``done`` with its outcome, each echoing the
nonce of its input. Everything here is read as hostile data: a message that is malformed, out
of order or over its size ends the job as ``error`` saying what was wrong (the sandbox's
convention), and the checks that say so are here, beside the limits they apply. The closed
loop's interface, as the sandbox drives it, is here too (:class:`ClosedLoop`), so the sandbox
needs neither the referee nor the loop's module.
"""

from __future__ import annotations

from typing import Any, Protocol

from ...errors import printable
from ...planner import PrepareProgress

#: The plan-size rule: the largest message (in practice, a plan's JSON) a case may send. A plan
#: of about 350,000 actions fits; a larger one is refused as ``error`` with its own message, so
#: a case can neither exhaust the harness's memory nor hold it parsing for minutes.
MAX_RESULT_BYTES = 64 * 2**20
#: A non-case job's one result: a preparation's ``prepared``, a probe's ``probed`` (with a JSON text).
JOB_RESULTS = {"prepare": "prepared", "probe": "probed"}
#: The largest ``progress`` message (bytes of its line); a larger one is a protocol fault.
MAX_PROGRESS_BYTES = 2048
#: The characters of a progress message's ``what`` the harness keeps (control characters escaped).
PROGRESS_TEXT = 120
#: The largest step count a progress message may name.
MAX_PROGRESS_STEPS = 10**9
#: Progress messages shown per second at most (a burst of :data:`PROGRESS_BURST`); more are read and dropped.
PROGRESS_RATE = 10.0
PROGRESS_BURST = 20
#: Progress messages a job may send in all; past them it is a flood, a protocol fault.
MAX_PROGRESS_MESSAGES = 200_000


class StepHooks(Protocol):
    """What the one loop that owns a closed-loop step (:meth:`ClosedLoop.step`) calls around it:
    the sandbox's I/O and its freezer."""

    def pause(self) -> None:
        """The harness is about to work on the step: the case stands still (no compute between calls)."""

    def resume(self) -> None:
        """The harness's work on the step is done."""

    def observe(self, data: bytes) -> None:
        """Hand the planner its next observation (one line of JSON) and start its call's clock."""

    def end(self) -> None:
        """The harness ended the run (step cap, broken rule): no next observation."""


class ClosedLoop(Protocol):
    """The closed loop as the sandbox drives it (:class:`earthbench.running.harness.steps.StepLoop`)."""

    def step(self, plan_json: str, compute_s: float, hooks: StepHooks) -> str:
        """One step, whole; returns what is wrong with it ('' when it was executed)."""

    def no_actions(self, compute_s: float) -> None:
        """A planner call that ended without actions (it said done, or a deadline or fault cut it short)."""


def check_done(msg: dict[str, Any], ready: bool, closed_loop: bool = False, prepare: bool | str = False) -> str:
    """Why a result message is malformed, or '' when it is well formed. ``prepare``: the job it is
    (``prepare``, ``probe``; True: ``prepare``), whose one result is ``prepared`` or ``probed`` (or an error)."""
    outcome = msg.get("outcome")
    job = "prepare" if prepare is True else (prepare or "")
    expected = JOB_RESULTS.get(job)
    if (outcome in JOB_RESULTS.values() or expected) and outcome != expected and outcome not in ("error", "memory"):
        return f"the {job or 'case'}'s result has outcome {clip(outcome)}"
    if expected and outcome == expected:
        return "" if ready and isinstance(msg.get("summary"), str) else f"the {job}'s result is malformed"
    if outcome not in ("plan", "error", "memory", "steps"):
        return f"the case's result has outcome {clip(outcome)}, not one of plan, error, memory, steps"
    if outcome == "steps" and not (closed_loop and ready):
        return "the case said its steps are done, but it " + ("runs open loop" if ready else "was not ready")
    if outcome == "plan" and closed_loop:
        return "the case sent a whole plan, but its configuration runs closed loop (one step at a time)"
    if not isinstance(msg.get("error", ""), str):
        return f"the case's result has an error text of type {type(msg['error']).__name__}, not a string"
    if not isinstance(msg.get("detail", {}), dict):
        return "the case's result has a detail that is not an object"
    if outcome == "plan":
        if not ready:
            return "the case sent a plan before it said it was ready"
        if not isinstance(msg.get("plan"), str):
            return f"the case's result has a plan of type {type(msg.get('plan')).__name__}, not a JSON text"
    return ""


def read_progress(msg: dict[str, Any], size: int, job: bool | str) -> PrepareProgress | str:
    """A ``progress`` message (``size`` bytes) as the harness keeps it, or why it is a protocol
    fault: only a preparation reports progress, ``done`` and ``total`` are whole numbers with
    0 ≤ done ≤ total ≤ :data:`MAX_PROGRESS_STEPS`, ``what`` a string; the line is at most
    :data:`MAX_PROGRESS_BYTES`. ``what`` is cut to :data:`PROGRESS_TEXT` characters, its
    control characters escaped (:func:`earthbench.errors.printable`)."""
    if job not in ("prepare", True):
        return "the job sent a progress message, but only a preparation reports progress"
    if size > MAX_PROGRESS_BYTES:
        return f"the preparation sent a progress message of {size:,} bytes, over the limit of {MAX_PROGRESS_BYTES:,}"
    done, total, what = msg.get("done"), msg.get("total"), msg.get("what", "")
    if not all(isinstance(n, int) and not isinstance(n, bool) for n in (done, total)) or not isinstance(what, str):
        return f"the preparation sent a malformed progress message: {clip(msg)}"
    assert isinstance(done, int) and isinstance(total, int)
    if not 0 <= done <= total <= MAX_PROGRESS_STEPS:
        return f"the preparation's progress says {done} of {total} steps (not 0 ≤ done ≤ total ≤ {MAX_PROGRESS_STEPS:,})"
    text = " ".join(what.split())[:PROGRESS_TEXT]
    return PrepareProgress(done, total, printable(text))


def too_large(n: int) -> str:
    return (f"the case's result is over the plan-size limit: more than {MAX_RESULT_BYTES / 2**20:.0f} MB of JSON "
            f"(read {n / 2**20:.0f} MB before it was refused)")


def clip(value: Any, n: int = 120) -> str:
    """A value from a job, short and printable, for an error message."""
    text = value.decode(errors="replace") if isinstance(value, bytes) else repr(value)
    return text if len(text) <= n else text[:n] + "…"
