"""Closed-loop execution, in the harness process: each step of a planner executed on the truth.

A closed-loop planner (docs/DESIGN.md §6) answers each :class:`~earthbench.planner.Observation`
with its next actions. :class:`StepLoop` is the one loop that owns a step (:meth:`StepLoop.step`),
with the sandbox's hooks around it (its clock and I/O, its freezer). It takes each answer as the harness received it, checks
it (a readable plan, not empty, starting no earlier than the executed actions end, within the
plan-size rule), executes it on the scenario's truth with the referee's
:class:`~earthbench.referee.Execution` (the verdict :func:`~earthbench.referee.judge` gives the
executed prefix, in time linear in the step), and builds the next observation from the referee's final state. The planner's process
never sees the truth and never judges anything.

:func:`observation` is the one place that turns the truth into what the planner sees.
"""

from __future__ import annotations

import dataclasses
import json
import statistics
from collections.abc import Sequence
from typing import Any

from ...errors import PlanFormatError
from ...motion import ABS_TOL
from ...plan import Move, Plan, Prediction
from ...planner import Observation, Planner
from ...referee import Execution, Verdict
from ...sensing import Stations, observe, scan_seconds
from ...world import Scenario
from .protocol import StepHooks


def observation(truth: Scenario, verdict: Verdict, step: int, stations: Stations | None = None) -> Observation:
    """What the planner sees after the actions ``verdict`` judged: :func:`~earthbench.sensing.observe`
    of the true terrain they left (a scan from where the working machine now stands, seeded
    with ``step`` and the loop's scan ``stations``; the soil's nominal class), the machines
    where they stand, the truck's load, the plan time the scan ends at (the actions' end plus
    :func:`~earthbench.sensing.scan_seconds`), what is left in the bucket."""
    m = truth.machines
    poses: dict[str, Any] = {f"{mid}_pose": verdict.final_poses[mid] for mid in m.ids if mid in verdict.final_poses}
    now = dataclasses.replace(truth, terrain=verdict.final_terrain)
    view = observe(now, pose=verdict.final_poses.get(truth.worker), step=step, stations=stations)
    view = dataclasses.replace(view, machines=dataclasses.replace(view.machines, **poses))
    t = verdict.makespan + scan_seconds(truth)
    return Observation(view, step, t, verdict.loaded_volume, verdict.final_turn, verdict.final_bucket)


def step_metrics(steps: Sequence[Sequence[float]]) -> dict[str, float | int | None]:
    """The harness's figures of a closed-loop run from its stored steps ``[(actions, compute_s), …]``.

    ``steps``: planner calls answered with actions; ``replans``: those after the first;
    ``step_compute_median_s``/``step_compute_max_s``: harness-measured time per call (the
    final call that said "done" included).
    """
    acting = sum(1 for n, _ in steps if n > 0)
    times = [float(c) for _, c in steps]
    return {
        "steps": acting,
        "replans": max(acting - 1, 0),
        "step_compute_median_s": statistics.median(times) if times else None,
        "step_compute_max_s": max(times) if times else None,
    }


class StepLoop:
    """The executed prefix of one closed-loop run and the state the next observation comes from."""

    def __init__(self, truth: Scenario, *, max_steps: int, max_bytes: int):
        self.truth, self.max_steps, self.max_bytes = truth, max_steps, max_bytes
        self.execution = Execution(truth)
        self.steps: list[tuple[int, float]] = []  # (actions, harness-measured compute seconds) per call
        self.predicted: list[float | None] = []
        self.bytes = 0
        self.verdict: Verdict | None = None
        self.ended = ""  # why the harness ended the run before the planner said done
        self.stations = Stations()  # where scans were taken: a scan from a station repeats its error
        self.stations.noise_step(truth.machines.pose(truth.worker), 0)  # the first scan's

    @property
    def t(self) -> float:
        """The plan time the next actions may start at: the executed actions' end, and the scan after them."""
        return self.verdict.makespan + scan_seconds(self.truth) if self.verdict is not None else 0.0

    def take(self, plan_json: str, compute_s: float) -> str:
        """Execute one step's plan; returns what is wrong with it ('' when it was executed)."""
        k = len(self.steps)
        self.bytes += len(plan_json)
        if self.bytes > self.max_bytes:
            return f"step {k}: the steps' plans together are over the plan-size limit of {self.max_bytes / 2**20:.0f} MB"
        try:
            plan = Plan.from_json(plan_json)
        except (PlanFormatError, TypeError, ValueError) as exc:
            return f"step {k}: the actions cannot be read: {exc}"
        if not plan.actions:
            return f"step {k}: no actions (a step returns at least one action, or says done)"
        t0 = self.t
        for n, a in enumerate(plan.actions):
            start = a.path[0][0] if isinstance(a, Move) else a.t_start
            if start < t0 - ABS_TOL:
                scan = scan_seconds(self.truth) if self.verdict is not None else 0.0
                return (f"step {k}: action {n} starts at t={start:.3f} s, before the executed actions end"
                        + (f" and the {scan:g} s scan after them" if scan else "") + f" (t={t0:.3f} s)")
        self.steps.append((len(plan.actions), compute_s))
        self.predicted.append(plan.predicted.volume)
        self.verdict = self.execution.execute(plan.actions)
        if not self.verdict.valid:
            self.ended = f"step {k} broke the referee's rules; the run ended there"
        elif len(self.steps) >= self.max_steps:
            self.ended = f"the planner did not say done within the step cap of {self.max_steps} steps; its executed actions were judged"
        return ""

    def step(self, plan_json: str, compute_s: float, hooks: StepHooks) -> str:
        """One step, whole, in this one place: the case stands still (``hooks.pause``), the step's
        actions are checked and executed on the truth and the next observation built, the case
        goes on (``hooks.resume``), and the observation is handed over (``hooks.observe``) or the
        run ends (``hooks.end``: the step cap, a broken rule). ``compute_s``: the harness-measured
        seconds of the call that answered. Returns what is wrong with the step ('' when executed)."""
        hooks.pause()
        try:
            problem = self.take(plan_json, compute_s)
            data = self.next_observation() if not (problem or self.ended) else b""
        finally:
            hooks.resume()
        if problem:
            return problem
        if self.ended:
            hooks.end()
        else:
            hooks.observe(data)
        return ""

    def no_actions(self, compute_s: float) -> None:
        """A call that ended without actions: the planner said done, or a deadline or a fault cut it short."""
        self.steps.append((0, compute_s))

    def next_observation(self) -> bytes:
        """The message that hands the planner its next observation (one line of JSON)."""
        assert self.verdict is not None
        obs = observation(self.truth, self.verdict, len(self.steps), self.stations)
        return json.dumps(obs.to_dict(compact=True)).encode() + b"\n"

    def plan(self) -> Plan:
        """The executed steps as one plan: what is stored, re-judged and replayed."""
        known = [v for v in self.predicted if v is not None]
        volume = sum(known) if known and len(known) == len(self.predicted) else None
        return Plan(self.execution.plan.actions, Prediction(volume=volume), {"closed_loop": True, "steps": [n for n, _ in self.steps]})


def run_closed_loop(planner: Planner, truth: Scenario, *, max_steps: int | None = None) -> Plan:
    """A closed-loop planner's run in this process, without the sandbox or its clocks (for
    ``earthbench plan`` and notebooks): the same observations and checks as under the harness.
    Raises :class:`~earthbench.errors.PlanFormatError` for a step the harness would refuse."""
    loop = StepLoop(truth, max_steps=max_steps or truth.budget.max_steps, max_bytes=2**62)
    first = observe(truth)
    obs = Observation(first)
    hooks = _InProcess()
    while not loop.ended:
        actions = planner.step(obs)
        if actions is None:
            break
        problem = loop.step(actions.to_json(), 0.0, hooks)
        if problem:
            raise PlanFormatError(problem)
        if not loop.ended:
            obs = Observation.from_dict(json.loads(hooks.data), first)
    return loop.plan()


class _InProcess:
    """The hooks of :func:`run_closed_loop`: no process to pause, the observation kept for the next call."""

    data = b""

    def pause(self) -> None:
        pass

    def resume(self) -> None:
        pass

    def observe(self, data: bytes) -> None:
        self.data = data

    def end(self) -> None:
        pass
