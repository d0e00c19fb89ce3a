"""The guarded run of a step on the device: one loop for every solver and coupling.

`GuardedRunner.run(steps)` calls a step function in chunks of at most `check_every` steps. Before
a chunk it backs up the protected arrays and clears the flags (`reset`); the chunk runs as captured
graphs (CUDA, or Warp's CPU graph) of at most `graph_steps` steps (a graph's memory grows with the
launches in it; one graph per length, dropped by `invalidate`); after it
`check(chunk)` reads the flags and returns an exception or None. On an exception the arrays are
restored, `restore()` re-derives what depends on them, and the exception is raised: no NaN is
ever left in the state. The only host round-trip is the check, once per chunk.
"""

from __future__ import annotations

import math

import warp as wp

from .checks import count, finite, plain, positive
from .device import run_steps


def world_shares(arrays: list, world: int, worlds: int) -> list:
    """Copies of world `world`'s share (the world-th of `worlds` equal blocks) of each of `arrays`."""
    copies = []
    for array in arrays:
        n = len(array) // worlds
        copy = wp.empty(n, dtype=array.dtype, device=array.device)
        wp.copy(copy, array, src_offset=world * n, count=n)
        copies.append(copy)
    return copies


class GuardedRunner:
    """Runs `step()` in guarded chunks. `protected()` lists the arrays to back up (called per chunk, so
    it may change); `reset()` clears the flags before a chunk; `check(chunk)` returns an exception or
    None after it; `restore()` runs after a failed chunk's arrays are put back; `modules` are the kernel
    modules a step launches (loaded before capture); `graph_steps` bounds the steps of one captured graph
    (None: a whole chunk)."""

    def __init__(self, step, *, protected, check, device, modules, capture: bool, check_every: int = 100,
                 reset=None, restore=None, graph_steps: int | None = None):  # fmt: skip
        self.step, self.protected, self.check = step, protected, check
        self.reset, self.restore = reset, restore
        self.device, self.modules, self.capture = device, tuple(modules), bool(capture)
        self.check_every = count("check_every", check_every, 1)
        self.graph_steps = None if graph_steps is None else count("graph_steps", graph_steps, 1)
        self._graphs = {}
        self._backups = None

    def world_backup(self, world: int, worlds: int) -> list:
        """Copies of world `world`'s share (of `worlds` equal blocks) of the last chunk's backups."""
        return world_shares(self._backups, world, worlds)

    def put_world(self, copies: list, world: int, worlds: int) -> None:
        """Write `world_backup` copies back into world `world`'s share of the protected arrays."""
        for array, copy in zip(self.protected(), copies):
            wp.copy(array, copy, dest_offset=world * (len(array) // worlds), count=len(copy))

    def invalidate(self) -> None:
        """Drop the captured graphs: they hold the launch arguments (dt, arrays, terms) they were captured with."""
        self._graphs.clear()

    def run(self, steps: int, done=None) -> None:
        """Run `steps` steps; `done(chunk)` is called after every chunk that passed its check."""
        steps = count("steps", steps, 0)
        finished = 0
        while finished < steps:
            chunk = min(self.check_every, steps - finished)
            arrays = self.protected()
            if self._backups is None or [b.shape for b in self._backups] != [a.shape for a in arrays]:
                self._backups = [wp.empty_like(a) for a in arrays]
            for backup, a in zip(self._backups, arrays):
                wp.copy(backup, a)
            if self.reset is not None:
                self.reset()
            run_steps(self.step, chunk, device=self.device, graphs=self._graphs, modules=self.modules,
                      capture=self.capture, graph_steps=self.graph_steps)  # fmt: skip
            failure = self.check(chunk)
            if failure is not None:
                for backup, a in zip(self._backups, arrays):
                    wp.copy(a, backup)
                if self.restore is not None:
                    self.restore()
                raise failure
            finished += chunk
            if done is not None:
                done(chunk)


class Stepper:
    """What every ready-to-run stepper shares: a solver, its `state`, its time step `dt`, a `runner`
    (GuardedRunner), `safety` (the fraction of the stability bound an automatic dt takes), and the
    clock (`time`, `steps`: the state's). `refresh()` runs before steps (the chemistry re-checks dt on
    a moved surface)."""

    time = property(lambda self: self.state.time, lambda self, t: setattr(self.state, "time", float(t)))
    steps = property(lambda self: self.state.steps, lambda self, n: setattr(self.state, "steps", int(n)))
    check_every = property(lambda self: self.runner.check_every)
    scheme = property(lambda self: self.solver.scheme)

    @staticmethod
    def checked_safety(safety) -> float:
        safety = positive("safety", safety)
        if safety > 1:
            raise ValueError(f"safety must lie in (0, 1], got {plain(safety)!r}")
        return safety

    def refresh(self) -> None:
        """Prepare the next steps (nothing here)."""

    def advance(self, steps: int = 1):
        """Advance `steps` time steps on the device; returns self. A failed check raises its error with
        the state restored to the chunk's start."""
        self.refresh()

        def done(chunk):
            self.state.steps += chunk
            self.state.time += chunk * self.dt

        self.runner.run(steps, done)
        return self

    def run_until(self, time: float):
        """Advance by whole steps to the first step at or after `time`; returns self."""
        time = finite("time", time)
        self.refresh()
        return self.advance(max(0, math.ceil((time - self.time) / self.dt - 1e-9)))
