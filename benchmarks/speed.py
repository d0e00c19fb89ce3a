"""Speed benchmark (issue 7): kernels and whole steps against mesh size, with the roofline floor.

    wavewarp bench speed --device cuda:0 --levels 3 4 5 6 7 8 --out benchmarks/results

Kernels (median time of one evaluation, replayed from a CUDA graph on GPU so that launch
latency is not counted twice): the Koiter energy + forces with the atomic scatter and with the
deterministic gather (`Shell(deterministic=True)`), the whole shell force (plus volume term),
the Laplace–Beltrami action K c, the ground contact (limit points, contact, friction, Lᵀ), one
mechanics step with the explicit and with the implicit ground (`Ground(solve="implicit")`), and
the vectorised NumPy baseline of the same energy and gradient (float64; `benchmarks/numpy_shell.py`)
with the ratio. Whole steps: the coupled walker step (one FHN step, the active reference, one
mechanics step with gravity, contact, friction and damping: `coupled.Walking` with one substep,
deformation-insensitive and sensitive) and the sphere walker's own step (dt_c = 0.5 with its
mechanics substeps), steps per second over `Walking.advance`, host checks included.

Roofline of the Koiter forces: the bytes every evaluation must move at least once (tables,
reference, positions, forces, energy density) over the measured copy bandwidth, and its
floating-point operations (counted from the kernel's loops) over the measured FMA throughput;
the floor is the larger. Writes speed_<device>.json and speed_<device>.png.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from datetime import date

import numpy as np
import warp as wp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from numpy_shell import NumpyShell  # noqa: E402

from wavewarp.coupled import Walking  # noqa: E402
from wavewarp.device import describe_device, device_tag, resolve_device  # noqa: E402
from wavewarp.dynamics import Ground, ShellDynamics  # noqa: E402
from wavewarp.io import write_png, write_result  # noqa: E402
from wavewarp.laplace import LaplaceBeltrami  # noqa: E402
from wavewarp.mesh import Mesh, icosphere  # noqa: E402
from wavewarp.shell import REGULAR_PATCHES, Shell  # noqa: E402
from wavewarp.walker import WalkerParameters, ground_lift  # noqa: E402
from wavewarp.initial import gaussian_pulse  # noqa: E402
from wavewarp.waves import FitzHughNagumo  # noqa: E402

RADIUS, THICKNESS, AC, MU_V = 25.0, 2.1, 0.1, 0.4  # the sphere walker (scenes/sphere_walker.py)
WALKER = vars(WalkerParameters())
PAPER_SHARPNESS = 0.1  # the paper's friction regularisation k_f (the explicit ground needs a finite one)


def seconds_per_call(call, device, budget: float, repeats: int = 5) -> float:
    """Median seconds of one `call()` (device work only): on CUDA a graph of a batch of calls is
    replayed; on the CPU the calls run in a loop. Batches are sized to take `budget` / repeats."""
    device = wp.get_device(device)
    with wp.ScopedDevice(device):
        call()
        wp.synchronize_device(device)
        start = time.perf_counter()
        call()
        wp.synchronize_device(device)
        batch = max(1, min(2000, int(budget / repeats / max(time.perf_counter() - start, 1e-7))))
        if device.is_cuda:
            with wp.ScopedCapture(device=device) as capture:
                for _ in range(batch):
                    call()
            run = lambda: wp.capture_launch(capture.graph)  # noqa: E731
        else:
            run = lambda: [call() for _ in range(batch)]  # noqa: E731
        run()
        wp.synchronize_device(device)
        timings = []
        for _ in range(repeats):
            start = time.perf_counter()
            run()
            wp.synchronize_device(device)
            timings.append((time.perf_counter() - start) / batch)
    return float(np.median(timings))


def walker_shell(level: int, device, dtype, deterministic=False, volume=True, **options):
    """The sphere walker's shell on a level-`level` icosphere resting on the ground (volume=False:
    without the volume penalty, the Koiter terms alone; `options`: Shell's force-kernel choices)."""
    mesh = icosphere(RADIUS, level)
    weight = WALKER["density"] * WALKER["gravity"] * 4 * np.pi * RADIUS**2
    touching, depth = ground_lift(mesh, weight, walker_ground())
    mesh = Mesh(mesh.vertices + [0.0, 0.0, touching - depth], mesh.triangles)
    penalty = MU_V * WALKER["young"] * THICKNESS / RADIUS**4 if volume else 0.0
    shell = Shell(mesh, thickness=THICKNESS, young=WALKER["young"], poisson=WALKER["poisson"], AC=AC, AI=0.0,
                  volume_penalty=penalty, deterministic=deterministic, **options, device=device,
                  dtype=dtype)  # fmt: skip
    return mesh, shell


def walker_ground() -> Ground:
    """The inertial walker's ground (docs/theory/dynamics.md, per limit point): the scenes' contact law with
    the paper's friction regularisation k_f = 0.1, solved explicitly (the walkers' own default is the
    implicit Coulomb ground; the "implicit ground" row times this ground solved implicitly)."""
    return Ground(stiffness=WALKER["stiffness"], damping=WALKER["contact_damping"], friction=WALKER["friction"],
                  sharpness=PAPER_SHARPNESS)  # fmt: skip


def dynamics_of(shell, omega=None):
    """The sphere walker's dynamics; `omega` (from an identical shell) skips the Lanczos estimate."""
    return ShellDynamics(shell, density=WALKER["density"], gravity=WALKER["gravity"], ground=walker_ground(),
                         damping=WALKER["damping"], omega=omega)  # fmt: skip


def koiter_counts(shell) -> dict:
    """Bytes each force evaluation must move at least once, and its floating-point operations.

    Bytes: per triangle the patch table (start, type, vertex indices); per quadrature point the
    active reference (ā, ā⁻¹, b̄: 12 scalars, the weight) read; per vertex x read and F written
    (forces alone: the energy density is written only when the energy is asked for). Flops per point (the kernel's loops): the jet
    (x, x,α, x,αβ: 6 × 3 multiply-adds per patch vertex), the same for the scatter (6 × 3), and
    ~150 for strains, stresses and the normal's derivative.
    """
    t, mesh = shell.tables.host, shell.mesh
    scalar = 4 if shell.scalar == wp.float32 else 8
    patch = int(np.diff(t.patch_start).mean() + 0.5)
    n_q = t.points_per_triangle * mesh.n_triangles
    bytes_moved = (4 * (len(t.patch_vertices) + 2 * mesh.n_triangles) + n_q * 13 * scalar
                   + mesh.n_vertices * 6 * scalar)  # fmt: skip
    flops = n_q * (2 * 2 * 6 * 3 * patch + 150)
    return {"bytes": bytes_moved, "flops": flops}


def machine_peaks(device) -> dict:
    """Measured copy bandwidth (bytes read + written per second) and multiply-add throughput."""
    device = wp.get_device(device)
    n = (256 if device.is_cuda else 16) * 2**20
    with wp.ScopedDevice(device):
        a, b = wp.zeros(n, dtype=wp.float32), wp.zeros(n, dtype=wp.float32)
        copy = seconds_per_call(lambda: wp.copy(b, a), device, 0.5)
        threads = (132 * 2048 * 4) if device.is_cuda else 64
        out = wp.zeros(threads, dtype=wp.float32)
        fma = seconds_per_call(lambda: wp.launch(fma_kernel, dim=threads, inputs=[FMA_ITERATIONS], outputs=[out]),
                               device, 0.5)  # fmt: skip
    return {"bandwidth_bytes_per_s": 2 * 4 * n / copy, "flops_per_s": threads * FMA_ITERATIONS * 8 * 2 / fma}


FMA_ITERATIONS = 4096


@wp.kernel
def fma_kernel(iterations: int, out: wp.array(dtype=wp.float32)):
    """Eight independent multiply-add chains per thread (float32): the arithmetic peak."""
    i = wp.tid()
    x = wp.vec4(float(i), 1.0, 2.0, 3.0)
    y = wp.vec4(0.5, float(i), 1.5, 2.5)
    for _ in range(iterations):
        x = wp.cw_mul(x, wp.vec4(0.999999)) + wp.vec4(1e-6)
        y = wp.cw_mul(y, wp.vec4(0.999999)) + wp.vec4(1e-6)
    out[i] = x[0] + x[1] + x[2] + x[3] + y[0] + y[1] + y[2] + y[3]


def kernel_rows(level: int, device, dtype: str, budget: float, numpy_baseline: bool, gather_max_level: int,
                staged_blocks=(), force_blocks=(), force_registers=(), regular_patches=()) -> list:  # fmt: skip
    """One level's kernel timings; the atomic force kernel in blocks of `force_blocks` threads, with at most
    `force_registers` registers a thread, and the staged force kernels (`staged_blocks`, triangles per block) also record their largest force difference from the
    atomic scatter's (the default launch, blocks of 64), relative to its largest force."""
    rows = []
    mesh, shell = walker_shell(level, device, dtype)
    rng = np.random.default_rng(level)
    x = mesh.vertices * (1 + 0.01 * rng.standard_normal((mesh.n_vertices, 1)))
    c = rng.random(mesh.n_vertices)
    shells = [("koiter forces, atomic scatter", dict())]
    shells += [("koiter forces, deterministic gather", dict(deterministic=True))] if level <= gather_max_level else []
    shells += [(f"koiter forces, atomic, {b} threads a block", dict(force_block=b)) for b in force_blocks]
    shells += [(f"koiter forces, atomic, regular patches {m}" + (f", {b} threads a block" if b else ""),
                dict(regular_patches=m, **(dict(force_block=b) if b else {})))
               for m in regular_patches for b in (force_blocks or [None])]  # fmt: skip
    shells += [(f"koiter forces, atomic, ≤ {r} registers", dict(force_registers=r)) for r in force_registers]
    shells += [(f"koiter forces, staged {b} per block", dict(staged_block=b)) for b in staged_blocks]
    reference = None
    for name, options in shells:
        koiter = walker_shell(level, device, dtype, volume=False, **options)[1]
        forces = koiter.forces(x, c)
        reference = forces if reference is None else reference
        rows.append(dict(kernel=name, seconds=seconds_per_call(lambda s=koiter: s.forces_device(s._x, s._forces),
                                                               device, budget), **koiter_counts(koiter),
                         max_relative_difference=float(np.abs(forces - reference).max() / np.abs(reference).max())))  # fmt: skip
    shell.forces(x, c)
    rows.append(dict(kernel="shell forces (koiter + volume)",
                     seconds=seconds_per_call(lambda: shell.forces_device(shell._x, shell._forces), device, budget)))  # fmt: skip
    for mode in regular_patches:  # the volume moments follow the choice: one triangle an item unless "general"
        whole = walker_shell(level, device, dtype, regular_patches=mode)[1]
        whole.forces(x, c)
        rows.append(dict(kernel=f"volume moments, regular patches {mode}",
                         seconds=seconds_per_call(lambda s=whole: s._launch_volume(s._x, False), device, budget)))
        rows.append(dict(kernel=f"shell forces (koiter + volume), regular patches {mode}",
                         seconds=seconds_per_call(lambda s=whole: s.forces_device(s._x, s._forces), device, budget)))
    operator = LaplaceBeltrami(mesh, device=device, dtype=dtype)
    with wp.ScopedDevice(operator.device):
        cw, out = wp.array(c.astype(shell._real), dtype=shell.scalar), wp.empty(mesh.n_vertices, dtype=shell.scalar)
    rows.append(dict(kernel="laplace-beltrami K c", seconds=seconds_per_call(lambda: operator.apply_device(cw, out),
                                                                             device, budget)))  # fmt: skip
    dynamics = dynamics_of(shell, omega=1.0)  # ω only sets dt, unused here
    solver, state = dynamics.solver, dynamics.state
    rows.append(dict(kernel="ground contact and friction",
                     seconds=seconds_per_call(lambda: solver.contact_forces(state.x, state.v), device, budget)))  # fmt: skip
    for name, ground in (("mechanics step, explicit ground", walker_ground()),
                         ("mechanics step, implicit ground (8 sweeps)", replace(walker_ground(), solve="implicit"))):
        stepper = ShellDynamics(shell, density=WALKER["density"], gravity=WALKER["gravity"], ground=ground,
                                damping=WALKER["damping"], omega=1.0)  # fmt: skip
        rows.append(dict(kernel=name, seconds=seconds_per_call(  # a short step: the shell stays at rest on the ground
            lambda st=stepper: st.solver.step(st.state, st.state, 1e-4), device, budget)))  # fmt: skip
    if numpy_baseline and dtype == "float64":
        baseline = NumpyShell(mesh, thickness=THICKNESS, young=WALKER["young"], poisson=WALKER["poisson"], AC=AC,
                              AI=0.0, volume_penalty=shell.volume_penalty)  # fmt: skip
        start = time.perf_counter()
        repeats = 0
        while time.perf_counter() - start < budget or repeats < 2:
            baseline.energy_and_forces(x, c)
            repeats += 1
        rows.append(dict(kernel="numpy shell forces (koiter + volume)", seconds=(time.perf_counter() - start) / repeats))
    for row in rows:
        row.update(level=level, triangles=mesh.n_triangles, vertices=mesh.n_vertices, dtype=dtype,
                   triangles_per_second=mesh.n_triangles / row["seconds"])  # fmt: skip
    return rows


def step_rows(level: int, device, dtype: str, budget: float) -> list:
    """Coupled walker steps per second: one substep (chemistry each mechanics step), and the
    sphere walker's own chemistry step dt_c = 0.5 with its mechanics substeps."""
    rows, omega = [], None
    for sensitive in (False, True):
        for chemistry_dt in (None, WALKER["dt"]):
            mesh, shell = walker_shell(level, device, dtype)
            dynamics = dynamics_of(shell, omega)
            omega = dynamics.omega_max
            operator = LaplaceBeltrami(mesh, mesh.vertices if sensitive else None, assembled=not sensitive, device=device,
                                       dtype=dtype)  # as the walker scenes  # fmt: skip
            c0, _ = gaussian_pulse(operator, 0, 1.5 * 0.15, gamma=WALKER["gamma"], radius=RADIUS)
            wave = FitzHughNagumo(operator, WALKER["gamma"], c0=c0, dt=chemistry_dt or dynamics.dt)
            walking = Walking(dynamics, wave, sensitive=sensitive)
            walking.advance(walking.check_every)  # compiles and captures
            steps = walking.check_every
            start = time.perf_counter()
            walking.advance(steps)
            wp.synchronize_device(shell.device)
            once = time.perf_counter() - start
            steps = max(steps, int(budget / once * steps) // steps * steps)
            start = time.perf_counter()
            walking.advance(steps)
            wp.synchronize_device(shell.device)
            seconds = (time.perf_counter() - start) / steps
            rows.append(dict(step="coupled walker step" + (", sensitive" if sensitive else ", insensitive"),
                             substeps=walking.substeps, chemistry_dt=wave.dt, mechanics_dt=dynamics.dt, level=level,
                             triangles=mesh.n_triangles, dtype=dtype, seconds=seconds, steps_per_second=1 / seconds,
                             mechanics_steps_per_second=walking.substeps / seconds))  # fmt: skip
    return rows


def chart(result: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.8))
    for dtype, style in (("float32", "-"), ("float64", "--")):
        names = sorted({r["kernel"] for r in result["kernels"] if r["dtype"] == dtype})
        for k, name in enumerate(names):
            rows = sorted((r for r in result["kernels"] if r["dtype"] == dtype and r["kernel"] == name),
                          key=lambda r: r["triangles"])  # fmt: skip
            left.loglog([r["triangles"] for r in rows], [r["triangles_per_second"] for r in rows], style, marker="o",
                        color=f"C{k}", label=f"{name} ({dtype})")  # fmt: skip
    floor = sorted((r for r in result["kernels"] if r["dtype"] == "float32" and "floor_seconds" in r
                    and r["kernel"].endswith("atomic scatter")), key=lambda r: r["triangles"])  # fmt: skip
    if floor:
        left.loglog([r["triangles"] for r in floor], [r["triangles"] / r["floor_seconds"] for r in floor], "k:",
                    label="roofline floor, koiter forces float32")  # fmt: skip
    left.set_xlabel("triangles")
    left.set_ylabel("triangles per second")
    left.set_title(f"kernels, {result['device_name']}")
    left.legend(fontsize=6)
    for k, name in enumerate(sorted({r["step"] for r in result["steps"]})):
        for dtype, style in (("float32", "-"), ("float64", "--")):
            for substeps_one, marker in ((True, "o"), (False, "s")):
                rows = sorted((r for r in result["steps"] if r["step"] == name and r["dtype"] == dtype
                               and (r["substeps"] == 1) == substeps_one), key=lambda r: r["triangles"])  # fmt: skip
                if rows:
                    label = f"{name} ({dtype}, " + ("1 substep" if substeps_one else "dt_c = 0.5, mechanics steps") + ")"
                    values = [r["steps_per_second"] if substeps_one else r["mechanics_steps_per_second"] for r in rows]
                    right.loglog([r["triangles"] for r in rows], values, style, marker=marker, color=f"C{k}",
                                 label=label)  # fmt: skip
    right.axhline(1e4, color="grey", lw=0.8, ls=":")
    right.set_xlabel("triangles")
    right.set_ylabel("steps per second")
    right.set_title("coupled walker steps")
    right.legend(fontsize=6)
    fig.tight_layout()
    write_png(fig, path, dpi=110)


def report(rows: list, peaks: dict) -> None:
    """Add the roofline floor and the NumPy ratio to one level's rows, and print them."""
    numpy = next((r["seconds"] for r in rows if r["kernel"].startswith("numpy")), None)
    for row in rows:
        if "bytes" in row:
            row["floor_seconds"] = max(row["bytes"] / peaks["bandwidth_bytes_per_s"], row["flops"] / peaks["flops_per_s"])
            row["times_floor"] = row["seconds"] / row["floor_seconds"]
        if numpy and row["kernel"] == "shell forces (koiter + volume)":
            row["speedup_vs_numpy"] = numpy / row["seconds"]
        print(f"{row['triangles']:>9d} tri {row['dtype']} {row['kernel']:38s} {row['seconds'] * 1e3:9.4f} ms "
              f"{row['triangles_per_second']:9.3e} tri/s" + (f"  {row['times_floor']:.1f}x floor" if "times_floor" in row
              else "") + (f"  x{row['speedup_vs_numpy']:.1f} vs NumPy" if "speedup_vs_numpy" in row else "")
              + (f"  max |dF|/max|F| {row['max_relative_difference']:.1e}" if "max_relative_difference" in row else ""),
              flush=True)  # fmt: skip


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench speed", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--levels", type=int, nargs="+", default=[3, 4, 5, 6, 7, 8], help="icosphere levels (kernels)")
    parser.add_argument("--step-levels", type=int, nargs="+", default=[3, 4, 5],
                        help="levels of the walker steps (level 6 at the scene's dt_c: 1,386 substeps, slow to capture)")
    parser.add_argument("--numpy-max-level", type=int, default=6, help="skip the NumPy baseline above this level")
    parser.add_argument("--gather-max-level", type=int, default=7, help="skip the deterministic gather above this level")
    parser.add_argument("--staged-blocks", type=int, nargs="*", default=None,
                        help="triangles per block of the staged force kernel's rows (default 64 128 256 on CUDA, 1 on "
                             "the CPU)")  # fmt: skip
    parser.add_argument("--force-blocks", type=int, nargs="*", default=[],
                        help="threads a block of extra rows of the atomic force kernel (its default launch: 64)")
    parser.add_argument("--force-registers", type=int, nargs="*", default=[],
                        help="registers a thread of extra rows of the atomic force kernel, the rest spilled (CUDA)")
    parser.add_argument("--regular-patches", nargs="*", default=[], choices=REGULAR_PATCHES,
                        help="extra rows of the atomic force kernel with these kernels for the regular patches (each "
                             "at every --force-blocks size), and of the volume moments and the whole shell force with "
                             "each")  # fmt: skip
    parser.add_argument("--budget", type=float, default=0.5, help="seconds per timing")
    parser.add_argument("--out", default="benchmarks/results")
    parser.add_argument("--quick", action="store_true", help="levels 2 and 3, short timings (smoke test)")
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    levels, step_levels, budget = ([2, 3], [2], 0.05) if args.quick else (args.levels, args.step_levels, args.budget)
    staged = args.staged_blocks if args.staged_blocks is not None else ([1] if device.is_cpu else [64, 128, 256])
    peaks = machine_peaks(device)
    print(f"{device.alias}: copy bandwidth {peaks['bandwidth_bytes_per_s']:.3g} B/s, "
          f"multiply-add {peaks['flops_per_s']:.3g} flop/s (float32)")  # fmt: skip
    kernels, steps = [], []
    for level in levels:
        rows = []
        for dtype in ("float32", "float64"):
            rows += kernel_rows(level, device.alias, dtype, budget, level <= args.numpy_max_level, args.gather_max_level,
                                staged, args.force_blocks, args.force_registers, args.regular_patches)  # fmt: skip
        kernels += rows
        report(rows, peaks)
    for level in step_levels:
        for dtype in ("float32", "float64"):
            for row in step_rows(level, device.alias, dtype, budget):
                steps.append(row)
                print(f"{row['triangles']:>9d} tri {dtype} {row['step']:36s} substeps {row['substeps']:3d}: "
                      f"{row['steps_per_second']:9.3e} steps/s, {row['mechanics_steps_per_second']:9.3e} mechanics "
                      "steps/s", flush=True)  # fmt: skip
    result = dict(benchmark="speed", date=date.today().isoformat(), **describe_device(device), peaks=peaks,
                  kernels=kernels, steps=steps)  # fmt: skip
    write_result(result, args.out, f"speed_{device_tag(device)}", chart)
    return 0


if __name__ == "__main__":
    sys.exit(main())
