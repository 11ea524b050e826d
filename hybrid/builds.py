"""Which build of the step runs, serial or parallel: measured as the simulation runs.

The per-point passes are compiled twice (`hybrid.kernel.kernel_twin`); the two
builds agree to the last bit, so a run may switch between them at any step
without changing its result (only the simulated time t0 + k h, summed per
compiled call, may move in its last bits where a call is cut, as when
`step(n)` is called in two halves). Which one is faster depends on the mesh, the
machine and what else runs on it: on a machine whose cores other programs
take, threads that wait for each other make the parallel build many times
slower than one thread. `BuildChoice` times them against each other on the
run's own steps and runs the faster.
"""

from __future__ import annotations

import math

from .kernel import limit_threads, usable_threads

__all__ = ["BUILDS", "BuildChoice"]

#: how a simulation picks its build: timed as it runs, or fixed
BUILDS = ("auto", "serial", "parallel")


class BuildChoice:
    """Which build of the per-point passes a simulation runs, measured as it runs.

    `build="auto"` on a model that may run in parallel (`MembraneArrays.parallel`)
    with more than one usable thread (`hybrid.kernel.usable_threads`: numba's
    threads, at most the CPUs of the process's affinity): the run starts serial,
    its first step (which loads the compiled code) untimed. A probe cuts the next
    steps into `PROBE_PAIRS` pairs of pieces, serial and parallel in turn, each of
    about `PROBE_S` of wall time (at least a step); the build with the smaller
    mean time per step over its pieces runs on (the mean, not the fastest piece:
    under load the parallel build's pieces vary most, and a lucky one says
    nothing of the run). A probe stops after its first pair when one build is
    `PROBE_CLEAR` times the faster. The pieces are the run's own steps, so a probe
    costs only what its slower pieces lose. Time here is the time spent stepping
    (what the pieces took), not the wall clock: pauses between calls count for
    nothing. Probes come again after `PROBE_EVERY_S`, doubling while the choice
    holds up to `PROBE_MAX_S`, and early when the running build gets `SLOWDOWN`
    times slower than when chosen (another program took a core); never so often
    that their loss exceeds `PROBE_BUDGET` of the stepping time. "serial" or
    "parallel" fix the build. (A scene with Python schedules, stepped one step
    per call, keeps the build it has: serial, unless fixed.)

    The simulation asks `chunk(remaining)` for (parallel, steps) and reports each
    piece with `record(parallel, steps, seconds)`.
    """

    PROBE_S = 4e-3
    PROBE_PAIRS = 3
    PROBE_EVERY_S = 0.5
    PROBE_MAX_S = 8.0
    PROBE_BUDGET = 0.02
    PROBE_CLEAR = 3.0
    SLOWDOWN = 1.5

    def __init__(self, may_parallel: bool, build: str = "auto"):
        if build not in BUILDS:
            raise ValueError(f"build: expected one of {BUILDS}, received {build!r}")
        self.build = build
        self.threads = usable_threads()
        limit_threads(self.threads)  # never more threads than CPUs to run them
        self.active = build == "auto" and bool(may_parallel) and self.threads > 1
        self.parallel = build == "parallel"
        self.steps = {False: 0, True: 0}  # steps run by each build
        self.us_per_step = {False: math.nan, True: math.nan}  # each build's last piece
        self.probes = 0
        self._probe: list[bool] = []  # the builds of the probe's pieces to come
        self._spent = {False: [0.0, 0], True: [0.0, 0]}  # the probe's seconds and steps per build
        self._clock = 0.0  # s spent stepping (the pieces recorded): the probes' clock
        self._next_probe = 0.0  # _clock of the next probe: at the start
        self._every = self.PROBE_EVERY_S
        self._last_probe = 0.0
        self._budget_wait = 0.0  # s after a probe that keep its loss within PROBE_BUDGET
        self._chosen_us = math.nan  # the running build's time per step when chosen

    def chunk(self, remaining: int) -> tuple[bool, int]:
        """(parallel, steps) of the next piece of `remaining` steps."""
        if not self.active or remaining < 2:
            return self.parallel, remaining
        if self._clock == 0.0:  # the first call loads the compiled code: not a piece to time
            return self.parallel, 1
        if not self._probe:
            if self._clock < self._next_probe:
                return self.parallel, remaining
            self._probe = [self.parallel, not self.parallel] * self.PROBE_PAIRS
            self._spent = {False: [0.0, 0], True: [0.0, 0]}
        us = self.us_per_step[self._probe[0]]
        size = max(1, int(self.PROBE_S * 1e6 / us)) if us > 0 else 1
        return self._probe[0], min(size, remaining)

    def record(self, parallel: bool, steps: int, seconds: float) -> None:
        """A piece of `steps` steps of that build took `seconds` of wall time."""
        self.steps[parallel] += steps
        if not self.active or steps <= 0:
            return
        self._clock += seconds
        us = seconds * 1e6 / steps
        self.us_per_step[parallel] = us
        if self._probe and self._probe[0] == parallel:
            self._probe.pop(0)
            self._spent[parallel][0] += seconds
            self._spent[parallel][1] += steps
            (ser_s, ser_n), (par_s, par_n) = self._spent[False], self._spent[True]
            if ser_n and par_n and not 1 / self.PROBE_CLEAR < par_s * ser_n / (ser_s * par_n) < self.PROBE_CLEAR:
                self._probe = []  # one build is clearly the faster: no more pieces of the slower
            if not self._probe:
                self._decide()
        elif not self._probe and us > self.SLOWDOWN * self._chosen_us and seconds > 0.5 * self.PROBE_S:
            # the running build slowed down: time both again as soon as the budget allows
            self._every = self.PROBE_EVERY_S
            self._next_probe = min(self._next_probe, self._last_probe + self._budget_wait)

    def _decide(self) -> None:
        mean = {p: seconds / steps for p, (seconds, steps) in self._spent.items()}
        parallel = mean[True] < mean[False]
        self._ratio = mean[True] / mean[False]
        (won_s, won_n), (lost_s, lost_n) = self._spent[parallel], self._spent[not parallel]
        loss = max(0.0, lost_s - lost_n * won_s / won_n)  # what the slower pieces cost beyond the faster
        self._every = self.PROBE_EVERY_S if parallel != self.parallel else min(2 * self._every, self.PROBE_MAX_S)
        self.parallel = parallel
        self._chosen_us = won_s * 1e6 / won_n
        self.probes += 1
        self._last_probe = self._clock
        self._budget_wait = loss / self.PROBE_BUDGET
        self._next_probe = self._last_probe + max(self._every, self._budget_wait)

    def summary(self) -> dict:
        """What ran: the build asked for, the threads, the build running now, the
        steps of each, the probes and the last one's parallel / serial mean time
        per step."""
        ratio = self._ratio if self.probes else None
        return {
            "build": self.build,
            "threads": self.threads,
            "parallel_now": self.parallel,
            "serial_steps": self.steps[False],
            "parallel_steps": self.steps[True],
            "probes": self.probes,
            "parallel_to_serial": ratio,
        }
