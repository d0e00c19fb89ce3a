"""Batched worlds (issue 28): aggregate world-steps per second of N walker worlds stepped together in
one batched run, against the same worlds run one after another in the same process.

    wavewarp bench batch --device cuda:0 --levels 4 5 --worlds 1 4 16 64 256 --out benchmarks/results

The sphere walker (R = 25, h = 0.084 R, μV = 0.4 Yh/R⁴, the ground), deformation-sensitive FHN at
the scene's dt_c = 0.5 with its mechanics substeps (`coupled.Walking`); world w has its own AC
(0 … 0.3 over the worlds) and rest shape (seeded noise, 0.01 R by default); each settles on the ground first (the
scene's 40 time units) and the wave starts from the scene's Gaussian at vertex 0. Every N shares one ω (the stiffest
world's, AC = 0.3, over the references the wave visits); the contact damping in the bound is the
strictest world's, so the mechanics substeps per chemistry step grow by up to 2% with N (the
mechanics world-steps/s count them). Per level and N: the batched run's coupled steps per second × N (world-steps/s,
and × substeps the mechanics world-steps/s); the sequential baseline runs min(N, 4) of the same
worlds one after another, each as its own single-world run, and reports their aggregate (the same
for every N: a single run's rate); the ratio of the two; the seconds to set the batch up (tables, settling); and
the Koiter force kernel alone on the union (its time against the roofline floor of `bench speed`).

The quasi-static rows (`--relaxations`): N noisy spheres (R = 10, h = 0.05 R, μV = 10 Yh/R⁴, seeded
noise per world) with their own AC (0.1 … 0.3) relax from rest under c = 0.5 by nonlinear CG, each
world with its own line search and convergence (`Shell.relax` on the union), against the same
relaxations one after another; the batch runs until its slowest world converges, so its CG passes
are the largest world's count. Timed on the second relaxation of each shell (the first compiles and
captures the loop).

The scene rows (`--scenes`): N worlds of the `buckling-modes` scene (the steep front, k = 3, with AI
from 10.5 to 13.5 over the worlds, seeded noise; `adaptive_dt` and `self_contact` off, 4 frames to
t = 4) as one batched run (`build_batch`, then `run`), against min(N, 2) of the same worlds run one
after another through the scene's own `build` and the driver; both timed from build to the last
frame, after a first run that compiles. A batch runs each relaxation until its slowest world
converges. Writes batch_<device>.json and batch_<device>.png.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from datetime import date

import numpy as np
import warp as wp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from speed import WALKER, koiter_counts, machine_peaks, seconds_per_call, walker_ground  # noqa: E402

from wavewarp.coupled import Walking  # noqa: E402
from wavewarp.driver import simulate  # noqa: E402
from wavewarp.device import describe_device, device_tag, resolve_device  # noqa: E402
from wavewarp.dynamics import ShellDynamics  # noqa: E402
from wavewarp.initial import gaussian_pulse  # noqa: E402
from wavewarp.io import write_png, write_result  # noqa: E402
from wavewarp.laplace import LaplaceBeltrami  # noqa: E402
from wavewarp.mesh import Mesh, icosphere  # noqa: E402
from wavewarp.parameters import load_scene, resolve  # noqa: E402
from wavewarp.runs import imperfect, mean_edge  # noqa: E402
from wavewarp.shell import Shell  # noqa: E402
from wavewarp.walker import bound_over_reference_range, ground_lift  # noqa: E402
from wavewarp.waves import FitzHughNagumo  # noqa: E402

RADIUS, THICKNESS, MU_V, AC_MAX = 25.0, 2.1, 0.4, 0.3


def world_meshes(level: int, count: int, noise: float) -> list:
    """`count` sphere walkers on the ground: the icosphere, seeded noise × R per world, lifted to touch."""
    sphere = icosphere(RADIUS, level)
    weight = WALKER["density"] * WALKER["gravity"] * 4 * np.pi * RADIUS**2
    touching, depth = ground_lift(sphere, weight, walker_ground())
    lift = np.array([0.0, 0.0, touching - depth])
    return [Mesh(imperfect(sphere, noise * RADIUS, seed).vertices + lift, sphere.triangles) for seed in range(count)]


def walking(meshes: list, couplings: list, device, dtype: str, omega=None) -> Walking:
    """The coupled walker of `meshes` as one batched run (one world each, AC from `couplings`); `omega`
    sets the mechanics' bound (None: the Lanczos estimate over the wave's references)."""
    mesh = Mesh.union(meshes) if len(meshes) > 1 else meshes[0]
    shell = Shell(mesh, THICKNESS, WALKER["young"], WALKER["poisson"], AC=couplings, AI=0.0,
                  volume_penalty=MU_V * WALKER["young"] * THICKNESS / RADIUS**4, device=device, dtype=dtype)  # fmt: skip
    dynamics = ShellDynamics(shell, density=WALKER["density"], gravity=WALKER["gravity"], ground=walker_ground(),
                             damping=WALKER["damping"], omega=omega)  # fmt: skip
    if omega is None:
        dynamics.set_time_step(None, bound_over_reference_range(dynamics))
    dynamics.run_until(WALKER["settle"])
    operator = LaplaceBeltrami(mesh, dynamics.state.x, assembled=False, device=device, dtype=dtype)  # as the scenes
    single = LaplaceBeltrami(meshes[0], device=device, dtype=dtype)
    width = 1.5 * mean_edge(meshes[0])  # the scene's default
    c0, _ = gaussian_pulse(single, 0, width / RADIUS, gamma=WALKER["gamma"], radius=RADIUS)
    wave = FitzHughNagumo(operator, WALKER["gamma"], c0=np.tile(c0, len(meshes)), dt=WALKER["dt"],
                          mass_corrections=WALKER["mass_corrections"])  # fmt: skip
    return Walking(dynamics, wave, sensitive=True)


def steps_per_second(walk: Walking, budget: float) -> float:
    """Coupled steps per second over `Walking.advance` (guarded chunks, host checks included), after a
    warm-up chunk that compiles and captures."""
    walk.advance(walk.check_every)
    device = walk.shell.device
    steps = walk.check_every
    start = time.perf_counter()
    walk.advance(steps)
    wp.synchronize_device(device)
    once = time.perf_counter() - start
    steps = max(steps, int(budget / once * steps) // steps * steps)
    start = time.perf_counter()
    walk.advance(steps)
    wp.synchronize_device(device)
    return steps / (time.perf_counter() - start)


def level_rows(level: int, worlds: list, device, dtype: str, budget: float, peaks: dict, noise: float) -> list:
    meshes = world_meshes(level, max(worlds), noise)
    couplings = list(np.linspace(0.0, AC_MAX, max(worlds)))
    omega = walking([meshes[-1]], [AC_MAX], device, dtype).dynamics.omega_max  # the stiffest world
    sequential = []
    for w in range(min(4, max(worlds))):  # the same worlds, one single run after another
        walk = walking([meshes[w]], [couplings[w]], device, dtype, omega)
        sequential.append(steps_per_second(walk, budget / 4))
    seconds_per_world_step = float(np.mean([1 / rate for rate in sequential]))
    rows = []
    for n in worlds:
        start = time.perf_counter()
        walk = walking(meshes[:n], couplings[:n] if n > 1 else [couplings[0]], device, dtype, omega)
        build = time.perf_counter() - start
        rate = steps_per_second(walk, budget)
        shell = walk.shell
        x = wp.clone(walk.dynamics.state.x)
        forces = seconds_per_call(lambda: shell.forces_device(x, walk.dynamics.solver._forces), device, budget / 2)
        counts = koiter_counts(shell)
        floor = max(counts["bytes"] / peaks["bandwidth_bytes_per_s"], counts["flops"] / peaks["flops_per_s"])
        per_world = meshes[0].n_triangles
        row = dict(kind="walker", level=level, worlds=n, noise_R=noise, triangles_per_world=per_world,
                   triangles=n * per_world, dtype=dtype, substeps=walk.substeps, build_seconds=build, steps_per_second=rate,
                   world_steps_per_second=n * rate, mechanics_world_steps_per_second=n * rate * walk.substeps,
                   sequential_world_steps_per_second=1 / seconds_per_world_step,
                   speedup_vs_sequential=n * rate * seconds_per_world_step, shell_forces_seconds=forces,
                   shell_forces_times_floor=forces / floor)  # fmt: skip
        rows.append(row)
        print(f"level {level} {n:4d} worlds ({row['triangles']:>8d} tri) {dtype}: {row['world_steps_per_second']:9.3e} "
              f"world-steps/s ({row['mechanics_world_steps_per_second']:9.3e} mechanics), "
              f"x{row['speedup_vs_sequential']:.1f} vs sequential; shell forces {forces * 1e3:.3f} ms = {row['shell_forces_times_floor']:.1f}x floor; "
              f"set up (tables, settling) in {build:.1f} s", flush=True)  # fmt: skip
    return rows


def relax_seconds(meshes: list, couplings: list, device, dtype: str) -> tuple:
    """(seconds, CG iterations per world) of relaxing `meshes` as one batch from rest under c = 0.5."""
    mesh = Mesh.union(meshes) if len(meshes) > 1 else meshes[0]
    shell = Shell(mesh, 0.5, 1.0, AC=couplings, volume_penalty=10.0 * 0.5 / 10.0**4, device=device, dtype=dtype)
    shell.relax(mesh.vertices, 0.5, method="ncg")  # compiles and captures
    start = time.perf_counter()
    shell.relax(mesh.vertices, 0.5, method="ncg")
    seconds = time.perf_counter() - start
    histories = shell.relax_history if len(meshes) > 1 else [shell.relax_history]
    return seconds, [len(history) - 1 for history in histories]


def relaxation_rows(level: int, worlds: list, device, dtype: str, noise: float) -> list:
    sphere = icosphere(10.0, level)
    meshes = [imperfect(sphere, noise * 10.0, seed) for seed in range(max(worlds))]
    couplings = list(np.linspace(0.1, 0.3, max(worlds)))
    alone = [relax_seconds([meshes[w]], [couplings[w]], device, dtype)[0] for w in range(min(4, max(worlds)))]
    seconds_per_world = float(np.mean(alone))
    rows = []
    for n in worlds:
        seconds, iterations = relax_seconds(meshes[:n], couplings[:n], device, dtype)
        row = dict(kind="relaxation", level=level, worlds=n, noise_R=noise, triangles_per_world=sphere.n_triangles,
                   triangles=n * sphere.n_triangles, dtype=dtype, seconds=seconds,
                   world_relaxations_per_second=n / seconds,
                   sequential_world_relaxations_per_second=1 / seconds_per_world,
                   speedup_vs_sequential=n * seconds_per_world / seconds, iterations_max=max(iterations),
                   iterations_mean=float(np.mean(iterations)))  # fmt: skip
        rows.append(row)
        print(f"level {level} {n:4d} worlds relaxing ({row['triangles']:>8d} tri) {dtype}: {n / seconds:9.3e} "
              f"world-relaxations/s, x{row['speedup_vs_sequential']:.1f} vs sequential; CG iterations max "
              f"{row['iterations_max']}, mean {row['iterations_mean']:.0f}", flush=True)  # fmt: skip
    return rows


def scene_worlds(level: int, count: int, dtype: str, frames: int, t_end: float) -> tuple:
    """(scene module, parameters, seeds) of `count` buckling-modes worlds, AI from 10.5 to 13.5."""
    module = load_scene("buckling-modes")
    fixed = [f"level={level}", "k=3", "adaptive_dt=false", "self_contact=false", f"frames={frames}", f"t_end={t_end}",
             f"dtype={dtype}"]  # fmt: skip
    if level > 3:  # a batch keeps one dt: the automatic one (level 3: 0.25) outruns the front's falling bound
        fixed.append(f"dt={0.25 * 2.0 ** (3 - level)}")  # the bound scales with the edge
    ps = [resolve(module.Parameters, None, [*fixed, f"AI={a}"]) for a in np.linspace(10.5, 13.5, count)]
    return module, ps, list(range(count))


def scene_seconds(module, ps: list, seeds: list, device) -> tuple:
    """(seconds, wave steps) from build to the last frame: one batched run of the worlds, or (one world) the
    scene's single run through the driver."""
    start = time.perf_counter()
    if len(ps) > 1:
        batch = module.build_batch(ps, seeds=seeds, device=device, report=lambda message: None)
        results = batch.run()
        assert all(r["status"] == "done" for r in results), [r["stopped"] for r in results]
        return time.perf_counter() - start, batch.steps
    run = module.build(ps[0], device=device, seed=seeds[0], report=lambda message: None)
    outcome = simulate(run, [])
    assert outcome.failure is None, outcome.failure
    return time.perf_counter() - start, run.steps


def scene_rows(level: int, worlds: list, device, dtype: str, frames: int = 4, t_end: float = 4.0) -> list:
    module, ps, seeds = scene_worlds(level, max(worlds), dtype, frames, t_end)
    scene_seconds(module, ps[:2], seeds[:2], device)  # compiles both paths' kernels
    scene_seconds(module, ps[:1], seeds[:1], device)
    alone = [scene_seconds(module, ps[w:w + 1], seeds[w:w + 1], device)[0] for w in range(min(2, max(worlds)))]
    seconds_per_world = float(np.mean(alone))
    rows = []
    for n in worlds:
        seconds, steps = scene_seconds(module, ps[:n], seeds[:n], device)
        row = dict(kind="scene", scene=module.NAME, level=level, worlds=n, triangles_per_world=20 * 4**level,
                   triangles=n * 20 * 4**level, dtype=dtype, seconds=seconds, wave_steps=steps,
                   world_runs_per_second=n / seconds, sequential_world_runs_per_second=1 / seconds_per_world,
                   speedup_vs_sequential=n * seconds_per_world / seconds)  # fmt: skip
        rows.append(row)
        print(f"level {level} {n:4d} {module.NAME} worlds ({row['triangles']:>8d} tri) {dtype}: {seconds:8.2f} s, "
              f"x{row['speedup_vs_sequential']:.1f} vs one after another ({seconds_per_world:.2f} s each)", flush=True)  # fmt: skip
    return rows


def chart(result: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.5))
    walkers = [r for r in result["rows"] if r.get("kind", "walker") == "walker"]
    for k, level in enumerate(sorted({r["level"] for r in walkers})):
        rows = [r for r in walkers if r["level"] == level]
        label = f"{rows[0]['triangles_per_world']:,} triangles per world"
        left.loglog([r["worlds"] for r in rows], [r["mechanics_world_steps_per_second"] for r in rows], "o-",
                    color=f"C{k}", label=f"batched, {label}")  # fmt: skip
        left.loglog([r["worlds"] for r in rows], [r["sequential_world_steps_per_second"] * r["substeps"] for r in rows],
                    "s--", color=f"C{k}", label=f"one after another, {label}")  # fmt: skip
        right.semilogx([r["worlds"] for r in rows], [r["speedup_vs_sequential"] for r in rows], "o-", color=f"C{k}",
                       label=f"walkers, {label}")  # fmt: skip
    relaxations = [r for r in result["rows"] if r.get("kind") == "relaxation"]
    for k, level in enumerate(sorted({r["level"] for r in relaxations})):
        rows = [r for r in relaxations if r["level"] == level]
        right.semilogx([r["worlds"] for r in rows], [r["speedup_vs_sequential"] for r in rows], "^:", color=f"C{k + 2}",
                       label=f"relaxations, {rows[0]['triangles_per_world']:,} triangles per world")  # fmt: skip
    scenes = [r for r in result["rows"] if r.get("kind") == "scene"]
    for k, level in enumerate(sorted({r["level"] for r in scenes})):
        rows = [r for r in scenes if r["level"] == level]
        right.semilogx([r["worlds"] for r in rows], [r["speedup_vs_sequential"] for r in rows], "v-.", color=f"C{k + 4}",
                       label=f"{rows[0]['scene']} runs, {rows[0]['triangles_per_world']:,} triangles per world")  # fmt: skip
    left.set_xlabel("worlds N")
    left.set_ylabel("mechanics world-steps per second")
    left.set_title(f"sphere walkers, {result['device_name']}" if walkers else "(no walker rows)")
    if walkers:
        left.legend(fontsize=7)
    right.axhline(10, color="grey", lw=0.8, ls=":")
    right.set_xlabel("worlds N")
    right.set_ylabel("batched / one after another")
    right.set_title("aggregate speed-up")
    right.legend(fontsize=7)
    fig.tight_layout()
    write_png(fig, path, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench batch", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--levels", type=int, nargs="+", default=[4, 5], help="icosphere levels (4: 5,120 triangles)")
    parser.add_argument("--worlds", type=int, nargs="+", default=[1, 4, 16, 64, 256])
    parser.add_argument("--max-triangles", type=int, default=5_300_000, help="skip batches larger than this")
    parser.add_argument("--dtype", default="float32", choices=("float32", "float64"))
    parser.add_argument("--noise", type=float, default=0.01, help="rest-shape noise per world / R (seeded)")
    parser.add_argument("--budget", type=float, default=2.0, help="seconds per timing")
    parser.add_argument("--out", default="benchmarks/results")
    parser.add_argument("--relaxations", action="store_true", help="also the quasi-static rows (batched relaxations)")
    parser.add_argument("--no-walkers", action="store_true", help="skip the walker rows")
    parser.add_argument("--scenes", action="store_true", help="also whole buckling-modes runs (batched scene worlds)")
    parser.add_argument("--quick", action="store_true", help="level 1, 1 and 3 worlds, short timings (smoke test)")
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    levels, worlds, budget = ([1], [1, 3], 0.05) if args.quick else (args.levels, sorted(args.worlds), args.budget)
    peaks = machine_peaks(device)
    rows = []
    for level in levels:
        fitting = [n for n in worlds if n * 20 * 4**level <= args.max_triangles]
        if not args.no_walkers:
            rows += level_rows(level, fitting, device.alias, args.dtype, budget, peaks, args.noise)
        if args.relaxations or args.quick:
            rows += relaxation_rows(level, fitting, device.alias, args.dtype, args.noise)
        if args.scenes and not args.quick:
            rows += scene_rows(level, fitting, device.alias, args.dtype)
    if args.quick:  # the scene's rows at level 2 (the smallest icosphere its tables take), one frame
        rows += scene_rows(2, worlds, device.alias, args.dtype, frames=1, t_end=1.0)
    result = dict(benchmark="batch", date=date.today().isoformat(), **describe_device(device), peaks=peaks, rows=rows)
    write_result(result, args.out, f"batch_{device_tag(device)}", chart)
    return 0


if __name__ == "__main__":
    sys.exit(main())
