"""Batched quasi-static waves (docs/theory/batches.md): N sphere worlds of one mesh topology, one wave
and one relaxation for all.

The worlds' meshes (each its own seeded imperfection) form one `Mesh.union`; one Model holds them with
per-world couplings and moduli (AC, AI, h, Y, μV); the telegraph wave steps every world in the same
launches, and every relaxation is one nonlinear-CG loop with a line search and a convergence test per
world. Worlds never interact, so in deterministic float64 each world equals its own single run bit for
bit (tests/test_batch_quasistatic.py). A world whose wave blows up, whose surface lowers the stability
bound below the shared dt, or whose relaxation fails (unless accept_unconverged) is stopped alone
(`QuasiStatic.stopped`); the others go on.

    batch = buckling_modes.build_batch([p0, p1, p2], seeds=[0, 0, 0])
    results = batch.run()        # one dict per world: status, stopped, frames, measurements, parameters

Batches take the fixed dt (adaptive_dt=false: one dt steps every world) and no self-contact (the
worlds share one space).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .balance import ChemicalBalance
from .batch import WorldsRun, check_batch
from .chemistry import telegraph_total
from .laplace import LaplaceBeltrami
from .mesh import Mesh, icosphere
from .parameters import as_dict
from .quasistatic import (COUNTER, frame_clock, initial_values, quasi_static_coupling, quasi_static_model,
                          relaxation_measurements)
from .runs import imperfect, mean_edge, scene_mesh


class WorldView:
    """What a scene's profile and measurement functions read of a run (`size`, `origin`, `mesh`, `p`,
    `front_start`, `profiles`, `profile_time`), for one world of a batch."""

    def __init__(self, mesh: Mesh, p, *, size: float, origin, front_start: float):
        self.mesh, self.p, self.size, self.origin, self.front_start = mesh, p, size, origin, front_start
        self.profiles, self.profile_time = [], 0.0


class QuasiStaticBatch(WorldsRun):
    """Quasi-static wave worlds stepped together: `meshes` (one topology) and parameters `ps`, one per
    world; `size`, `origin`, `initial`, `t_end`, `rule`, `profile`, `measure` as QuasiStaticWaveRun's.
    The worlds share the wave's dt (the strictest world's bound) and its relaxation schedule."""

    def __init__(self, name: str, meshes: list, ps: list, *, size: float, origin, initial: dict, t_end: float,
                 front_start: float = 0.0, rule: str = "3", device=None, profile=None, measure=None, report=print):  # fmt: skip
        ps = list(ps)
        check_batch(ps)
        if len(meshes) != len(ps):
            raise ValueError(f"a batch needs one mesh per world: {len(meshes)} meshes for {len(ps)} parameter sets")
        p = self.p = ps[0]
        self.name, self.ps, self.worlds, self.world_meshes = name, ps, len(ps), list(meshes)
        self.mesh = Mesh.union(meshes)
        self.model = quasi_static_model(self.mesh, ps, size=size, rule=rule, device=device)
        self.shell = self.model.shell
        self.operator = self.model.operator()
        n = self.vertices = self.mesh.vertices_per_world
        self._slices = [slice(w * n, (w + 1) * n) for w in range(self.worlds)]
        # each world's initial values on its own operator, exactly as its single run makes them
        initials = [initial_values(LaplaceBeltrami(mesh, rule=rule, device=device, dtype=p.dtype), origin, initial,
                                   gamma=p.gamma, size=size) for mesh in meshes]  # fmt: skip
        c0, v0 = (np.concatenate(values) for values in zip(*initials))
        edge = min(mean_edge(mesh) for mesh in meshes)
        dt, relax_every, self.steps_per_frame, self.frames = frame_clock(
            p, t_end, edge, self.model.wave(self.operator, c0=c0).stable_dt, report)  # fmt: skip
        self.wave = self.model.wave(self.operator, c0=c0, v0=v0, dt=dt)
        self.coupled = quasi_static_coupling(self.shell, self.wave, ps, relax_every, size)
        self.resolved = [as_dict(replace(q, dt=dt, relax_every=relax_every, frames=self.frames,
                                         relax_iterations=self.coupled.max_iterations)) for q in ps]  # fmt: skip
        mass, c, rate = self.operator.mass(), self.wave.concentration(), self.wave.velocity()
        self.invariants = [(float(mass[s] @ c[s]), float(mass[s] @ rate[s])) for s in self._slices]
        self.balance = ChemicalBalance(self.mesh, sensitive=p.sensitive, rule=rule, device=device, dtype=p.dtype)
        self.series = {"positions": (n, 3), "concentration": (n,), "concentration_rate": (n,),
                       **{COUNTER + name: () for name in self.coupled.TALLIES}}  # the bookkeeping, for a resume
        self.frame_interval = self.steps_per_frame * dt
        self.views = [WorldView(mesh, q, size=size, origin=np.asarray(origin, dtype=np.float64), front_start=front_start)
                      for mesh, q in zip(meshes, ps)]  # fmt: skip
        self._profile, self._measure = profile, measure

    @property
    def stopped(self) -> dict:
        """World -> the error that stopped it."""
        return self.coupled.stopped

    def advance_frame(self) -> None:
        """Coupled steps of every world to the next multiple of the frame interval."""
        end = (round(self.time / self.frame_interval) + 1) * self.frame_interval
        while end - self.time > 0.5 * self.coupled.chemistry_steps * self.wave.dt:
            self.coupled.step()

    def world_frames(self, state: dict) -> list:
        """Every world's frame of the batch's `state.to_frame()`, as `QuasiStaticWaveRun.frame` (the series
        of `self.series`)."""
        return [{**{name: values[s] for name, values in state.items() if name in self.series},
                 **{COUNTER + name: np.array(value) for name, value in self.coupled.counters(w).items()}}
                for w, s in enumerate(self._slices)]  # fmt: skip

    def record(self, state: dict, frames: list, time: float | None = None) -> None:
        """The chemical balance of every world and each running world's profile at the current frame (or at
        `time`, a stored frame's)."""
        time = self.time if time is None else time
        expected = [telegraph_total(total, rate, self.p.alpha, self.wave.dt, time) for total, rate in self.invariants]
        self.balance.record(time, state["positions"], state["concentration"], expected)
        if self._profile is None:
            return
        for w, (view, frame) in enumerate(zip(self.views, frames)):
            if w not in self.stopped:
                view.profile_time = time
                view.profiles.append((time, self._profile(view, frame["positions"])))

    def replay_frame(self, time: float, frames: list) -> None:
        """Every world's stored frame at `time` (a resumed batch) into the balance and the profiles."""
        joined = {name: np.concatenate([frame[name] for frame in frames]) for name in ("positions", "concentration")}
        self.record(joined, frames, time)

    def restore(self, time: float, frames: list) -> None:
        """Continue every world from its stored frame at `time`: positions, c, c_t, the time and each world's
        relaxation bookkeeping (as `QuasiStaticWaveRun.restore`)."""
        joined = {name: np.concatenate([frame[name] for frame in frames])
                  for name in ("positions", "concentration", "concentration_rate")}  # fmt: skip
        self.coupled.state.assign_frame(joined)
        self.coupled.restore(joined["positions"])
        self.wave.steps = int(round(time / self.wave.dt))
        self.wave.time = float(time)  # as the uninterrupted run summed it
        for w, frame in enumerate(frames):
            self.coupled.restore_counters({name: frame[COUNTER + name] for name in self.coupled.TALLIES}, w)

    def _record(self, writers, stopped_after: dict) -> None:
        state = self.coupled.state.to_frame()  # one read of the device state per frame
        frames = self.world_frames(state)
        self.record(state, frames)
        for w, frame in enumerate(frames):
            if writers and w not in stopped_after:
                writers[w].add_frame(self.time, frame)

    def measurements(self, w: int, time: float) -> dict:
        """World w's measurements, as its `QuasiStaticWaveRun.measurements` (a stopped world's at its stop)."""
        x = self.coupled.positions()
        frozen = self.coupled.frozen(w)
        finite = frozen is None or np.all(np.isfinite(frozen["x"]))  # a world stopped on NaN positions has none
        if frozen is not None and finite:
            x[self._slices[w]] = frozen["x"]
        volume = float(np.atleast_1d(self.shell.volume(x))[w]) if finite else float("nan")
        out = {"time": time, "volume": volume, **relaxation_measurements(self.coupled, w),
               **self.balance.measurements(w)}  # fmt: skip
        if self._measure is not None:
            out.update(self._measure(self.views[w]))
        return out


def sphere_wave_batch(name: str, ps: list, *, seeds, initial=None, front_start: float = 0.0, device=None,
                      report=print, profile=None, measure=None, end_fraction=1.0) -> QuasiStaticBatch:  # fmt: skip
    """`sphere_wave_run`'s worlds as one batch: world w is ps[w] with its rest shape perturbed by
    ps[w].noise × R, seeded by seeds[w]. Refuses what one batch cannot share: the adaptive step and
    self-contact."""
    ps, seeds = list(ps), [int(s) for s in seeds]
    if len(seeds) != len(ps):
        raise ValueError(f"a batch needs one seed per world: {len(seeds)} seeds for {len(ps)} parameter sets")
    check_batch(ps)
    p = ps[0]
    refused = {"adaptive_dt": "one dt steps every world: a world whose surface lowers the bound below it is "
                              "stopped alone",
               "self_contact": "the worlds overlap in space, and self-contact would push them apart"}  # fmt: skip
    for switch, why in refused.items():
        if getattr(p, switch, False):
            raise ValueError(f"a batch of {name} worlds needs --set {switch}=false ({why}), or run the points one "
                             "by one (--batch 1)")  # fmt: skip
    R = p.radius
    mesh = scene_mesh(None, lambda: icosphere(R, p.level), report, size=("level", p.level, icosphere), device=device)
    meshes = [imperfect(mesh, q.noise * R, seed) for q, seed in zip(ps, seeds)]
    if initial is None:
        initial = {"kind": "gaussian", "sigma": p.width / R, "distance": "arc"}
    return QuasiStaticBatch(name, meshes, ps, size=R, origin=np.array([0.0, 0.0, R]), initial=initial,
                            t_end=p.t_end or end_fraction * math.pi * R / p.gamma, front_start=front_start,
                            device=device, profile=profile, measure=measure, report=report)  # fmt: skip
