"""Batched walkers (docs/theory/batches.md): N walker worlds of one mesh topology stepped together.

The worlds' meshes form one `Mesh.union`; one Model holds them with per-world couplings and moduli
(AC, AI, h, Y, μV) and rest shapes (noise, elongation), one State holds every world's x, v, c, w,
and every solver steps all worlds in the same launches and the same captured graph. Worlds never interact: every reduction (volume,
rigid-body sums, the trace) is per world, so in deterministic float64 each world equals its own
single run bit for bit (tests/test_batch.py). A world that blows up is stopped at the start of the
chunk it failed in and reported; the others go on.

    batch = sphere_walker_batch([p0, p1, p2], seeds=[0, 1, 2], device="cuda")
    results = batch.run()        # one dict per world: status, stopped, measurements, parameters
"""

from __future__ import annotations

import contextlib
from dataclasses import fields, replace

import numpy as np
import warp as wp

from .balance import ChemicalBalance, FirstArrival, arrival_measurements
from .chemistry import fhn_kinetic_period
from .coupled import Walking
from .driver import FAILURES
from .initial import gaussian_pulse
from .laplace import LaplaceBeltrami
from .measurements import BodyRotation, locomotion
from .mesh import Mesh
from .parameters import as_dict
from .runs import WaveClock, imperfect, mean_edge
from .walker import (AUTO_DT_SAFETY, TRACE_COLUMNS, check_walker_steps, place_walker, restore_walk,
                     implicit_step, settled_walker_dynamics, walker_model)

PER_WORLD = ("AC", "AI", "thickness", "young", "mu_v", "tau_m", "mirror", "noise", "elongation")  # and the seed: the rest is shared


def check_batch(ps: list) -> None:
    """ValueError unless the worlds' parameters differ only in PER_WORLD."""
    if not ps:
        raise ValueError("a batch needs at least one world")
    first = ps[0]
    own = [f.name for f in fields(first) if f.name in PER_WORLD]  # the scene's per-world parameters
    for w, p in enumerate(ps[1:], 1):
        differ = [f.name for f in fields(first)
                  if f.name not in PER_WORLD and getattr(p, f.name) != getattr(first, f.name)]  # fmt: skip
        if differ:
            raise ValueError(f"world {w} differs from world 0 in {', '.join(differ)}: the worlds of a batch share "
                             f"every parameter but {', '.join(own)} (and the seed); run the others in another "
                             "batch")  # fmt: skip


class WorldsRun(WaveClock):
    """What a batched run's frames share: `run` steps every world frame by frame and reports each; the
    run provides `frames`, `stopped` (world -> error), `resolved` (per world), `advance_frame()`,
    `_record(writers, stopped_after)` and `measurements(w, time)`; a run that can be resumed also
    `replay_frame(time, frames)` and `restore(time, frames)`."""

    @property
    def resumable(self) -> bool:
        return hasattr(self, "restore")

    def run(self, progress=None, writers=None, replay=None) -> list:
        """Every frame (`progress(frames done)` after each); `writers`, one trajectory writer per world
        (wavewarp/trajectory.py; entered here), take each world's frames until it stops. `replay`: per world,
        the (time, frame) pairs its trajectory holds (as many for every world, the writers resumed after
        them): replayed into the measurements, and the run goes on from the last. Returns one result per
        world: status ("done", or "stopped" with its error), the frames it completed (the first included),
        its measurements (a stopped world's at its stop) and resolved parameters."""
        stopped_after, stop_times = {}, {}  # world -> the frames it completed before it stopped; its time then
        with contextlib.ExitStack() as stack:
            for writer in writers or ():
                stack.enter_context(writer)
            if replay:
                for stored in zip(*replay):  # one stored frame of every world
                    self.replay_frame(stored[0][0], [frame for _, frame in stored])
                self.restore(replay[0][-1][0], [frames[-1][1] for frames in replay])
            else:
                self._record(writers, stopped_after)
            for frame in range(len(replay[0]) - 1 if replay else 0, self.frames):
                try:
                    self.advance_frame()
                except FAILURES:  # every world has stopped
                    break
                finally:
                    for w in self.stopped:
                        stopped_after.setdefault(w, frame)
                        stop_times.setdefault(w, self.time)
                self._record(writers, stopped_after)
                if progress is not None:
                    progress(frame + 1)
            results = [self.result(w, stopped_after.get(w, self.frames), stop_times.get(w, self.time))
                       for w in range(self.worlds)]  # fmt: skip
            for writer, result in zip(writers or (), results):
                writer.set_measurements(result["measurements"])
        return results

    def result(self, w: int, frames: int, time: float) -> dict:
        """World w's result: status, its error if stopped, the frames it completed, its parameters and
        measurements."""
        stopped = self.stopped.get(w)
        return {"status": "stopped" if stopped else "done", "stopped": str(stopped) if stopped else None,
                "frames": frames + 1, "steps": self.steps, "parameters": self.resolved[w],
                "measurements": self.measurements(w, time)}  # fmt: skip


class WalkerBatch(WorldsRun):
    """Walker worlds stepped together: `meshes` (one topology) and parameters `ps` one per world; `radius`,
    `size`, `origin`, `bilayer`, `rule`, `mechanics_dt` as `WalkerRun`'s. The worlds share the chemistry's
    and the mechanics' steps: the strictest world's bounds (ω the largest over every world), or
    `mechanics_dt`."""

    def __init__(self, name: str, meshes: list, ps: list, *, radius: float, size: float, origin, bilayer: bool = False,
                 rule: str = "3", device=None, mechanics_dt=None, report=print):  # fmt: skip
        ps = list(ps)
        check_batch(ps)
        if len(meshes) != len(ps):
            raise ValueError(f"a batch needs one mesh per world: {len(meshes)} meshes for {len(ps)} parameter sets")
        p = ps[0]
        check_walker_steps(p)
        placed = [place_walker(mesh, q, origin) for mesh, q in zip(meshes, ps)]
        if len({pl.ground for pl in placed}) > 1:
            raise ValueError("the worlds' grounds differ (the area contact's automatic area per point follows each "
                             "world's area): set contact_area to one value for the batch")  # fmt: skip
        self.name, self.ps, self.radius, self.placed, self.worlds = name, ps, radius, placed, len(ps)
        self.world_meshes = [pl.mesh for pl in placed]
        self.mesh = Mesh.union(self.world_meshes)
        self.model = walker_model(self.mesh, ps, placed[0].ground, size=size, bilayer=bilayer, rule=rule, device=device)
        self.shell = self.model.shell
        # settle_dt: the step (overdamped: the pair of steps) while settling; a single run given it settles alike
        self.dynamics, self.settle_dt, _ = settled_walker_dynamics(self.model, p, mechanics_dt)
        self.period_kinetic = fhn_kinetic_period(p.nu, p.kappa, p.epsilon)
        n = self.vertices = self.mesh.vertices_per_world
        self._slices = [slice(w * n, (w + 1) * n) for w in range(self.worlds)]
        settled, mass = self.dynamics.positions(), self.dynamics.mass
        self.rest_heights = [float(mass[s] @ pl.mesh.vertices[:, 2] / m)
                             for s, pl, m in zip(self._slices, placed, self.dynamics.world_masses)]  # fmt: skip
        self.operator = self.model.operator(settled if p.sensitive else None, assembled=not p.sensitive)
        self.widths = [p.width or 1.5 * mean_edge(pl.mesh) for pl in placed]
        c0 = np.concatenate([self._pulse(pl, settled[s], width, rule, device)
                             for pl, s, width in zip(placed, self._slices, self.widths)])  # fmt: skip
        t_end = p.periods * self.period_kinetic
        dt = p.dt or min(AUTO_DT_SAFETY * self.model.wave(self.operator, c0=c0).stable_dt, t_end / p.frames)
        self.wave = self.model.wave(self.operator, c0=c0, dt=dt)
        mass, c = self.operator.mass(), self.wave.concentration()
        self.initial_totals = np.array([float(mass[s] @ c[s]) for s in self._slices])  # as WalkerRun's total()
        self.balance = ChemicalBalance(self.mesh, sensitive=p.sensitive, rule=rule, device=device, dtype=p.dtype)
        self.rotation = BodyRotation(self.dynamics.mass, self.worlds)
        self.arrival = FirstArrival(c0, device=self.shell.device, scalar=self.shell.scalar)
        self.steps_per_frame = max(1, round(t_end / p.frames / self.wave.dt))
        with wp.ScopedDevice(self.shell.device):
            self._origins = wp.array([w * n + pl.origin_vertex for w, pl in enumerate(placed)], dtype=wp.int32)
            self._trace_row = wp.zeros(self.worlds, dtype=wp.int32)
            columns = self.worlds * (TRACE_COLUMNS - 1)
            self._trace_rows = wp.zeros((self.steps_per_frame, columns), dtype=self.shell.scalar)
        if p.mechanics == "overdamped-implicit":
            self.dynamics.set_time_step(implicit_step(p, dt))
        self.coupled = Walking(self.dynamics, self.wave, sensitive=p.sensitive, recorder=self._record_trace_row,
                               ramp=p.ramp)  # fmt: skip
        self.frames = max(1, round(t_end / (self.steps_per_frame * self.wave.dt)))
        self.resolved = [{**as_dict(replace(q, width=width, dt=dt)), "mechanics_dt": self.dynamics.dt,
                          "substeps": self.coupled.substeps, "period_kinetic": self.period_kinetic}
                         for q, width in zip(ps, self.widths)]  # fmt: skip
        self.traces = [sample[None] for sample in self._samples()]  # every chemistry step, as WalkerRun.trace
        self._frame_traces = [np.repeat(trace, self.steps_per_frame, axis=0) for trace in self.traces]  # the last frame's
        n = self.vertices
        self.series = {"positions": (n, 3), "velocities": (n, 3), "concentration": (n,), "inhibitor": (n,),
                       "reaction_amount": (), "reaction_per_vertex": (n,), "first_arrival": (n,),
                       "trace": (self.steps_per_frame, TRACE_COLUMNS)}  # fmt: skip  # each world's, as WalkerRun's

    def _pulse(self, placed, x, width: float, rule: str, device) -> np.ndarray:
        """World's initial c: the Gaussian on its own operator, exactly as its single run makes it."""
        p = self.ps[0]
        operator = LaplaceBeltrami(placed.mesh, x if p.sensitive else None, rule=rule, assembled=not p.sensitive,
                                   device=device, dtype=p.dtype)  # fmt: skip
        return gaussian_pulse(operator, placed.origin_vertex, width / self.radius, gamma=p.gamma, radius=self.radius)[0]

    def _per_world(self, values: np.ndarray) -> np.ndarray:
        """Σ over each world's vertices (the sums its single run takes)."""
        return np.array([float(np.sum(values[s])) for s in self._slices])

    def _samples(self) -> list:
        """Every world's trace row now (`WalkerRun._sample`), from one read of c and x."""
        c, x, mass = self.wave.c.numpy(), self.dynamics.positions(), self.dynamics.mass
        rows = []
        for s, placed, world_mass in zip(self._slices, self.placed, self.dynamics.world_masses):
            cw, xw = c[s], x[s]
            centre = mass[s] @ xw / world_mass
            rows.append(np.array([self.wave.time, cw[placed.origin_vertex], *centre, *xw[placed.origin_vertex]]))
        return rows

    def _record_trace_row(self) -> None:
        self.dynamics.solver.launch_trace_row(self.dynamics.state, self.wave.c, self._origins, self._trace_row,
                                              self._trace_rows)  # fmt: skip
        self.arrival.launch(self.wave.c)

    @property
    def stopped(self) -> dict:
        """World -> the error that stopped it."""
        return self.coupled.stopped

    def advance_frame(self) -> None:
        """One frame of coupled steps of every world; its trace rows are read once."""
        start = self.wave.steps
        self._trace_row.zero_()
        self.coupled.advance(self.steps_per_frame)
        times = (start + np.arange(1, self.steps_per_frame + 1)) * self.wave.dt
        rows = self._trace_rows.numpy().astype(np.float64)
        width = TRACE_COLUMNS - 1
        for w in range(self.worlds):
            kept = times <= self.stopped[w].time + 1e-9 * self.wave.dt if w in self.stopped else slice(None)
            self._frame_traces[w] = np.column_stack([times, rows[:, w * width:(w + 1) * width]])
            self.traces[w] = np.concatenate([self.traces[w], self._frame_traces[w][kept]])

    def world_frames(self) -> list:
        """Every world's frame at the current time, as `WalkerRun.frame` (the series of `self.series`)."""
        state = self.coupled.state.to_frame()
        produced = self.wave.produced_per_vertex()
        arrival = self.arrival.times(self.wave.dt)
        return [{**{name: values[s] for name, values in state.items()}, "reaction_per_vertex": produced[s],
                 "reaction_amount": np.array(float(np.sum(produced[s].astype(np.float64)))),
                 "first_arrival": arrival[s], "trace": self._frame_traces[w]}
                for w, s in enumerate(self._slices)]  # fmt: skip

    def replay_frame(self, time: float, frames: list) -> None:
        """Every world's stored frame at `time` (a resumed batch) into the balance, the rotation and the
        traces, as `record` and `advance_frame` took it when it was written."""
        positions = np.concatenate([frame["positions"] for frame in frames])
        produced = np.array([float(frame["reaction_amount"]) for frame in frames])
        self.balance.record(time, positions, np.concatenate([frame["concentration"] for frame in frames]),
                            self.initial_totals + produced)  # fmt: skip
        self.rotation.record(positions)
        for w, frame in enumerate(frames):
            rows = np.asarray(frame["trace"], dtype=np.float64)
            new = rows[:, 0] > self.traces[w][-1, 0] + 1e-9 * self.wave.dt  # the times after the last kept
            self.traces[w] = np.concatenate([self.traces[w], rows[new]])
            self._frame_traces[w] = rows

    def restore(self, time: float, frames: list) -> None:
        """Continue every world from its stored frame at `time` (as `WalkerRun.restore`)."""
        joined = {name: np.concatenate([frame[name] for frame in frames])
                  for name in ("positions", "velocities", "concentration", "inhibitor", "reaction_per_vertex",
                               "first_arrival")}  # fmt: skip
        restore_walk(self, {**joined, "time": time, "reaction_amount": 0.0}, self.ps[0].sensitive)

    def record(self) -> None:
        """The chemical balance of every world at the current frame."""
        produced = self._per_world(self.wave.produced_per_vertex().astype(np.float64))
        positions = self.dynamics.positions()
        self.balance.record(self.time, positions, self.wave.concentration(), self.initial_totals + produced)
        self.rotation.record(positions)

    def _record(self, writers, stopped_after: dict) -> None:
        """The balance of every world, and each running world's frame into its writer."""
        self.record()
        if writers:
            for w, frame in enumerate(self.world_frames()):
                if w not in stopped_after:
                    writers[w].add_frame(self.time, frame)

    def measurements(self, w: int, time: float) -> dict:
        """World w's measurements, as its `WalkerRun.measurements` (a stopped world's time its stop)."""
        placed = self.placed[w]
        return {"time": time, "mechanics_steps": self.steps * self.coupled.substeps,
                "contact_depth_R": placed.depth / self.radius, **self.balance.measurements(w),
                **arrival_measurements(self.arrival.times(self.wave.dt)[self._slices[w]]),
                **locomotion(self.traces[w], placed.forward, self.radius, self.rest_heights[w],
                             self.period_kinetic), **self.rotation.measurements(placed.forward, w)}  # fmt: skip


def walker_batch(name: str, recipe, ps: list, *, seeds, device=None, report=print, mechanics_dt=None,
                 rest_shapes=None) -> WalkerBatch:  # fmt: skip
    """A scene's walkers as one batch: `recipe(p, device=, report=)` gives the scene's noiseless mesh and
    options (`sphere_walker_recipe`, `box_walker_recipe`); world w is ps[w] with its rest shape
    perturbed by ps[w].noise × radius, seeded by seeds[w]; `mechanics_dt` as `WalkerBatch`'s;
    `rest_shapes(mesh)`, where given, one (V, 3) displacement of the scene's control points per world,
    added before the noise and the elongation."""
    ps, seeds = list(ps), [int(s) for s in seeds]
    if len(seeds) != len(ps):
        raise ValueError(f"a batch needs one seed per world: {len(seeds)} seeds for {len(ps)} parameter sets")
    check_batch(ps)
    mesh, options = recipe(ps[0], device=device, report=report)
    shapes = [mesh] * len(ps) if rest_shapes is None else displaced(mesh, rest_shapes(mesh), len(ps))
    meshes = [imperfect(shape, p.noise * options["radius"], seed) for shape, p, seed in zip(shapes, ps, seeds)]
    return WalkerBatch(name, meshes, ps, device=device, report=report, mechanics_dt=mechanics_dt, **options)


def displaced(mesh: Mesh, displacements, worlds: int) -> list:
    """One mesh per world: `mesh` with each world's (V, 3) displacement of its control points."""
    displacements = [np.asarray(d, dtype=np.float64) for d in displacements]
    if len(displacements) != worlds or any(d.shape != mesh.vertices.shape for d in displacements):
        raise ValueError(f"rest_shapes must give one {mesh.vertices.shape} displacement per world ({worlds} worlds): "
                         f"got {[d.shape for d in displacements]}")  # fmt: skip
    return [Mesh(mesh.vertices + d, mesh.triangles) for d in displacements]
