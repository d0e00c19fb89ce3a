"""Stability benchmark (issue 7, docs/theory/scenes.md): largest stable time steps against their bounds.

The largest stable time step of every explicit method against mesh size and thickness, against
the method's predicted bound.

    wavewarp bench stability --device cpu --out benchmarks/results [--quick] [--levels ...] [--shell-levels ...]

Defaults: chemistry on levels 2-5 (IMEX to level 3), shell dynamics and relaxation on levels 1-4 with
h/R = 0.01, 0.084, 0.3, float64 (`--dtypes float32 float64` for both), `--parts` to select.

Measured bound: bisection on dt / predicted in [0.5, 2] down to `--resolution` (default 0.2% of
the predicted bound). A trial runs a fixed number of steps with `check_dt=False` from a state
that excites every mode, the highest included, and is *unstable* when the stepper raises
BlowUpError ("blow-up": NaN/Inf or past its blowup_limit), its OscillationError ("flip-flop": the
FHN steppers' period-2 flip detector) or the watched deviation (max norm) grows past `growth` × its
initial value ("growth"); the measured bound is the largest dt found stable, the first unstable one
is reported beside it with the criterion that fired (`unstable_by`).

* Telegraph leapfrog, γ = R = 1, α = 0.001 (subdivision with p = 0 and p = 2 mass corrections,
  P1): bound 2 / (γ sqrt(λ_max(M̃⁻¹K))); c0 random in [0, 1e-3], v0 = 0; watched c, growth 1000;
  2000 steps. Below the bound every mode keeps its amplitude; past it by ε = dt/dt* - 1 the top
  mode grows by 1 + 2 sqrt(2ε) per step, so 2000 steps see ε ≳ 1e-5.
* FitzHugh–Nagumo explicit Euler, γ = 1, the paper's ν, κ: bound 2 / (γ² λ_max + L_f); 5000 steps (Euler's
  top mode grows by 1 + 2ε per step). "rest": c0 random in [0, 1e-3], the paper's ε, growth 1000 (the
  medium's own oscillatory instability grows at ~0.005 per time unit); there f'(0) = -ν, so the
  true limit is 2 / (γ² λ_max + ν) and the bound is conservative by (γ² λ_max + L_f) / (γ² λ_max + ν).
  "excited": c0 = 1 + the same noise, ε = 0 so the state stays at the kinetic fixed point c = 1,
  where f'(1) = -L_f: the bound is sharp there. The fixed point attracts, so below the bound every
  deviation decays; past it the cubic reaction can hold the growing mode in a bounded, spurious
  period-2 oscillation instead of blowing up, hence growth 2 (watched c - 1), kept as a backstop: the
  steppers' flip detector (OscillationError) stops that oscillation once its increments pass 1e-3,
  inside the chunk, so `unstable_by` reads "flip-flop" for the FHN rows (rest ones included).
* FHN IMEX, excited state: bound 2 / L_f, no diffusive limit (only the uniform mode, λ = 0, can
  lose stability); also reported as a multiple of the explicit bound on the same mesh; 2000 steps.
* Shell dynamics, symplectic Euler, no ground, no gravity, no damping: bound 2/ω, ω² = λ_max(M⁻¹H)
  by Lanczos. Rest sphere R = 1, Y = 1, ν = 0.33, density ρ = h (unit 3-D density), so ω ∝ 1/ℓ
  where stretching sets it and ∝ h/ℓ² where bending does; v0 normal with deviation `--velocity`
  (default 1e-6: the linear regime the bound describes); watched v, growth 1000; 2000 steps
  (leapfrog-like growth, as the telegraph). At finite amplitude (1e-3 on a level-1 sphere) the
  shell's geometric nonlinearity runs away slowly from about 0.99 × the bound.
* Quasi-static relaxation (`Shell.relax`) has no time step and so no stability bound (nonlinear CG
  with an Armijo line search: the energy falls monotonically). Its evidence is convergence:
  iterations to the default tolerance from the rest sphere under a Gaussian c (σ = 0.5, starfish
  AC = AI = 0.5, μV = 24 Y h / R⁴), across levels and thicknesses.

Predicted bounds are the code's own (`stable_dt`: power iteration on the device, Lanczos); the
chemistry rows add the bound from λ_max of the same operator by scipy (float64, host). Writes
stability_<device>.json and the chart stability_<device>.png (`_quick` appended with --quick).
"""

from __future__ import annotations

import argparse
import functools
import math
import os
import sys
import time
from datetime import date

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import warp as wp

from wavewarp.device import describe_device, device_tag, resolve_device
from wavewarp.dynamics import ShellDynamics
from wavewarp.io import write_json, write_png
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.relax import RelaxationError
from wavewarp.shell import Shell
from wavewarp.initial import gaussian_pulse
from wavewarp.waves import BlowUpError, FitzHughNagumo, OscillationError, Telegraph

NOISE = 1e-3  # amplitude of the random initial chemistry
STEPS = {"telegraph": 2000, "fhn-explicit": 5000, "fhn-imex": 2000, "dynamics": 2000}
GROWTH = {"default": 1e3, "attracting": 2.0}  # unstable: the deviation's max norm passes this × its initial one
CHUNK = 100  # steps between two looks at the state (and the steppers' own blow-up checks)
GAMMA, ALPHA = 1.0, 0.001  # unit sphere: the chemistry benchmark's setting
NU, KAPPA, EPSILON = -0.01, 1e-4, 0.005  # docs/theory/chemistry.md
TELEGRAPH = (("subdivision", 0), ("subdivision", 2), ("p1", 0))  # (discretization, mass corrections)
YOUNG = 1.0
RELAX_COUPLING = {"AC": 0.5, "AI": 0.5}  # starfish oocyte (docs/theory/scenes.md); μV = 24 Y h / R⁴
PARTS = ("telegraph", "fhn", "dynamics", "relax")


@functools.cache
def sphere(level):
    """The unit icosphere of one level, built once per run."""
    return icosphere(1.0, level)


@functools.cache
def operator(level, discretization, dtype, device):
    """One operator per configuration: its power-iteration vector warm-starts every stepper's bound."""
    return LaplaceBeltrami(sphere(level), discretization=discretization, device=device, dtype=dtype)


def noise(n):
    """Random data in [0, NOISE] with a fixed seed: every mode, the highest and the uniform one included."""
    return NOISE * np.random.default_rng(7).uniform(0.0, 1.0, n)


def reaction_slope(c, nu) -> float:
    """f'(c) of the FHN reaction f = c(1-c)(c-ν): the state's own rate, which sets the true limit."""
    return -3 * c * c + 2 * (1 + nu) * c - nu


def runs_away(advance, watched, steps, growth) -> str | None:
    """Why `steps` steps (in chunks of CHUNK) are unstable: "flip-flop" (OscillationError), "blow-up"
    (any other BlowUpError) or "growth" (the max norm of `watched()` past `growth` × its initial
    value); None when they are stable."""
    start = np.abs(watched()).max()
    for _ in range(0, steps, CHUNK):
        try:
            advance(CHUNK)
        except OscillationError:
            return "flip-flop"
        except BlowUpError:
            return "blow-up"
        if not np.abs(watched()).max() <= growth * start:
            return "growth"
    return None


def largest_stable(unstable, predicted, resolution) -> dict:
    """Bisection on dt / predicted in [0.5, 2] down to `resolution`: the largest ratio found stable
    and the smallest found unstable, with what made it unstable (`unstable(dt)`: a `runs_away`
    reason or None; a result at 0.5 or 2 means the bracket missed)."""
    low, high, trials, unstable_by = 0.5, 2.0, 0, None
    while high - low > resolution:
        ratio = 0.5 * (low + high)
        trials += 1
        reason = unstable(ratio * predicted)
        if reason:
            high, unstable_by = ratio, reason
        else:
            low = ratio
    return {"measured_dt": low * predicted, "first_unstable_dt": high * predicted, "ratio": low, "trials": trials,
            "unstable_by": unstable_by, "bracket_missed": low == 0.5 or high == 2.0}  # fmt: skip


@functools.cache
def reference_eigenvalue(level, discretization, dtype, device, corrections) -> float:
    """λ_max(W_p K) of the steppers' operator, assembled on the host and solved in float64 by scipy
    (ARPACK), independently of their power iteration."""
    op = operator(level, discretization, dtype, device)
    K, m = op.stiffness_matrix().astype(np.float64), op.mass().astype(np.float64)
    start = np.random.default_rng(1).uniform(-1.0, 1.0, len(m))
    if corrections == 0:
        scale = sp.diags(1.0 / np.sqrt(m))
        return float(sla.eigsh(scale @ K @ scale, k=1, which="LA", tol=1e-10, v0=start, return_eigenvectors=False)[0])
    Mc = op.mass_matrix()

    def weighted(y):  # W_p y = M⁻¹ Σ_j (I - M_c M⁻¹)^j y
        term = result = y / m
        for _ in range(corrections):
            term = term - (Mc @ term) / m
            result = result + term
        return result

    WK = sla.LinearOperator(K.shape, matvec=lambda x: weighted(K @ x), dtype=np.float64)
    return float(sla.eigs(WK, k=1, which="LR", tol=1e-10, v0=start, return_eigenvectors=False)[0].real)


def telegraph_row(level, discretization, corrections, dtype, device, resolution) -> dict:
    op = operator(level, discretization, dtype, device)
    c0 = noise(op.n_vertices)
    start = time.perf_counter()

    def make(dt=None, **kwargs):
        return Telegraph(op, GAMMA, ALPHA, c0=c0, dt=dt, mass_corrections=corrections, check_every=CHUNK, **kwargs)

    reference = make()
    predicted, eigenvalue = reference.stable_dt, reference.largest_eigenvalue
    exact = reference_eigenvalue(level, discretization, dtype, device, corrections)

    def unstable(dt):
        wave = make(dt, check_dt=False)
        return runs_away(wave.advance, lambda: wave.c.numpy(), STEPS["telegraph"], GROWTH["default"])

    row = largest_stable(unstable, predicted, resolution)
    reference_bound = 2.0 / (GAMMA * math.sqrt(exact))
    return {"method": "telegraph", "discretization": discretization, "mass_corrections": corrections, "level": level,
            "vertices": op.n_vertices, "dtype": dtype, "steps": STEPS["telegraph"], "growth": GROWTH["default"],
            "eigenvalue": eigenvalue, "reference_eigenvalue": exact, "predicted_dt": predicted,
            "reference_dt": reference_bound, **row, "ratio_to_reference": row["measured_dt"] / reference_bound,
            "seconds": time.perf_counter() - start}  # fmt: skip


def fhn_row(level, state, scheme, dtype, device, resolution) -> dict:
    """FHN on the unit sphere: state "rest" (c ≈ 0, the paper's ε) or "excited" (c ≈ 1, ε = 0)."""
    op = operator(level, "subdivision", dtype, device)
    base = 0.0 if state == "rest" else 1.0
    c0 = base + noise(op.n_vertices)
    epsilon = EPSILON if state == "rest" else 0.0
    method = f"fhn-{scheme}"
    start = time.perf_counter()

    def make(dt=None, **kwargs):
        return FitzHughNagumo(op, GAMMA, NU, KAPPA, epsilon, c0=c0, dt=dt, scheme=scheme, check_every=CHUNK, **kwargs)

    reference = make()
    predicted = reference.stable_dt
    exact = reference_eigenvalue(level, "subdivision", dtype, device, 0)
    slope = reaction_slope(base, NU)
    explicit_bound = 2.0 / (GAMMA**2 * exact + reference.reaction_lipschitz)
    linearised = 2.0 / (GAMMA**2 * exact - slope) if scheme == "explicit" else 2.0 / -slope  # top / uniform mode
    growth = GROWTH["default" if state == "rest" else "attracting"]

    def unstable(dt):
        wave = make(dt, check_dt=False)
        return runs_away(wave.advance, lambda: wave.c.numpy() - base, STEPS[method], growth)

    row = largest_stable(unstable, predicted, resolution)
    result = {"method": method, "state": state, "discretization": "subdivision", "mass_corrections": 0, "level": level,
              "vertices": op.n_vertices, "dtype": dtype, "steps": STEPS[method], "growth": growth,
              "eigenvalue": reference.largest_eigenvalue, "reference_eigenvalue": exact, "reaction_slope": slope,
              "predicted_dt": predicted,
              "reference_dt": explicit_bound if scheme == "explicit" else predicted, "linearised_dt": linearised,
              "expected_ratio": linearised / predicted, **row}  # fmt: skip
    result["ratio_to_reference"] = row["measured_dt"] / result["reference_dt"]
    if scheme == "imex":
        result["over_explicit_bound"] = row["measured_dt"] / explicit_bound
    result["seconds"] = time.perf_counter() - start
    return result


def dynamics_row(level, thickness, velocity, dtype, device, resolution) -> dict:
    mesh = sphere(level)
    start = time.perf_counter()
    shell = Shell(mesh, thickness, YOUNG, device=device, dtype=dtype)
    v0 = velocity * np.random.default_rng(7).standard_normal((mesh.n_vertices, 3))
    dynamics = ShellDynamics(shell, density=thickness, v0=v0, check_every=CHUNK)
    lanczos = time.perf_counter() - start
    predicted, omega = dynamics.stable_dt, dynamics.omega_max
    x0, v0 = dynamics.x.numpy().copy(), dynamics.v.numpy().copy()  # on the CPU numpy() is a view

    def unstable(dt):
        dynamics.x.assign(x0)
        dynamics.v.assign(v0)
        dynamics.set_time_step(dt, omega, check_dt=False)
        return runs_away(dynamics.advance, lambda: dynamics.v.numpy(), STEPS["dynamics"], GROWTH["default"])

    row = largest_stable(unstable, predicted, resolution)
    return {"method": "dynamics", "level": level, "vertices": mesh.n_vertices, "thickness": thickness,
            "edge_length": shell.edge_length, "velocity": velocity, "dtype": dtype, "steps": STEPS["dynamics"],
            "growth": GROWTH["default"], "omega": omega, "predicted_dt": predicted, **row, "lanczos_seconds": lanczos,
            "seconds": time.perf_counter() - start}  # fmt: skip


def relax_row(level, thickness, dtype, device) -> dict:
    mesh = sphere(level)
    c, _ = gaussian_pulse(operator(level, "subdivision", "float64", device), 0, 0.5, gamma=1.0)
    shell = Shell(mesh, thickness, YOUNG, volume_penalty=24 * YOUNG * thickness, **RELAX_COUPLING, device=device,
                  dtype=dtype)  # fmt: skip
    start = time.perf_counter()
    residuals = []
    try:
        shell.relax(mesh.vertices, c, callback=lambda iteration, energy, residual: residuals.append(residual))
        converged, message = True, ""
    except RelaxationError as error:
        converged, message = False, str(error)
    seconds = time.perf_counter() - start
    energies = shell.relax_history
    return {"method": "relax", "level": level, "vertices": mesh.n_vertices, "thickness": thickness, "dtype": dtype,
            "converged": converged, "iterations": len(energies) - 1, "final_residual": residuals[-1],
            "energy_monotone": bool(np.all(np.diff(energies) <= 1e-7 * abs(energies[0]))), "seconds": seconds,
            "message": message}  # fmt: skip


def series_label(row) -> str:
    if row["method"] == "dynamics":
        return f"shell dynamics, h = {row['thickness']:g} ({row['dtype']})"
    if row["method"] == "telegraph":
        return f"telegraph, {row['discretization']}, p = {row['mass_corrections']} ({row['dtype']})"
    return f"{row['method']}, {row['state']} ({row['dtype']})"


def chart(result, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ((ratios, chemistry), (dynamics, relax)) = plt.subplots(2, 2, figsize=(13, 10))
    series = {}
    for row in result["rows"]:
        series.setdefault(series_label(row), []).append(row)
    for label, rows in series.items():
        rows.sort(key=lambda r: r["vertices"])
        vertices = [r["vertices"] for r in rows]
        spread = [r["first_unstable_dt"] / r["predicted_dt"] - r["ratio"] for r in rows]
        bars = ratios.errorbar(vertices, [r["ratio"] for r in rows], yerr=[[0] * len(rows), spread], fmt="o-",
                               capsize=3, label=label)  # fmt: skip
        if rows[0].get("state") == "rest":  # the limit at rest, f'(0) = -ν, against the bound's L_f
            ratios.plot(vertices, [r["expected_ratio"] for r in rows], "--", color=bars[0].get_color())
        method = rows[0]["method"]
        if method == "dynamics":
            x, panel = [r["edge_length"] for r in rows], dynamics
        else:
            x, panel = vertices, chemistry
        marker = "x" if method == "fhn-imex" else "o"
        line = panel.loglog(x, [r["measured_dt"] for r in rows], marker, label=label)
        panel.loglog(x, [r["predicted_dt"] for r in rows], "-", color=line[0].get_color())
    ratios.axhline(1.0, color="k", lw=0.8)
    ratios.set_xscale("log")
    ratios.set_xlabel("vertices")
    ratios.set_ylabel("largest stable dt / predicted bound")
    ratios.set_title(f"bisection to {result['resolution']:.2%}: bar to the first unstable, dashed expected")
    chemistry.set_xlabel("vertices (unit sphere, γ = 1)")
    chemistry.set_ylabel("dt: measured (markers), predicted (lines)")
    chemistry.set_title("chemistry: explicit steppers (x: FHN IMEX, bound 2 / L_f)")
    dynamics.set_xlabel("mean control edge ℓ (R = 1)")
    dynamics.set_ylabel("dt: measured (markers), predicted 2/ω (lines)")
    dynamics.set_title("shell dynamics (ρ = h, Y = 1): ∝ ℓ stretching, ∝ ℓ²/h bending")
    by_thickness = {}
    for row in result["relax"]:
        by_thickness.setdefault((row["thickness"], row["dtype"]), []).append(row)
    for (thickness, dtype), rows in sorted(by_thickness.items()):
        rows.sort(key=lambda r: r["vertices"])
        relax.semilogx([r["vertices"] for r in rows], [r["iterations"] for r in rows], "o-",
                       label=f"h = {thickness:g} ({dtype})")  # fmt: skip
    relax.set_xlabel("vertices")
    relax.set_ylabel("nonlinear CG iterations to the default tolerance")
    relax.set_title("quasi-static relax: no time step, no bound; converges")
    for panel in (ratios, chemistry, dynamics, relax):
        if panel.get_legend_handles_labels()[0]:
            panel.legend(fontsize=7)
    fig.suptitle(f"wavewarp stability, {result['device_name']} ({result['date']})")
    fig.tight_layout()
    write_png(fig, path, dpi=110)


def save_json(args, device, result) -> str:
    """Write the result (also after every row, so an interrupted run keeps its rows)."""
    name = f"stability_{device_tag(device)}{'_quick' if args.quick else ''}"
    path = os.path.join(args.out, name + ".json")
    write_json(path, result)
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench stability", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", default="benchmarks/results")
    parser.add_argument("--quick", action="store_true", help="small meshes, coarse bisection (a CPU smoke test)")
    parser.add_argument("--levels", type=int, nargs="+", default=None, help="chemistry levels (default 2 3 4 5)")
    parser.add_argument("--imex-max-level", type=int, default=3, help="FHN IMEX rows up to here (default 3)")
    parser.add_argument("--shell-levels", type=int, nargs="+", default=None, help="dynamics, relax (default 1 2 3 4)")
    parser.add_argument("--thicknesses", type=float, nargs="+", default=None, help="h/R (default 0.01 0.084 0.3)")
    parser.add_argument("--velocity", type=float, default=1e-6, help="dynamics: initial velocity deviation (R = 1)")
    parser.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS), help="what to measure (default: all)")
    parser.add_argument("--dtypes", nargs="+", choices=("float32", "float64"), default=["float64"])
    parser.add_argument("--resolution", type=float, default=None, help="bisection width / bound (default 0.002)")
    args = parser.parse_args(argv)
    levels = args.levels or ([2] if args.quick else [2, 3, 4, 5])
    shell_levels = args.shell_levels or ([1] if args.quick else [1, 2, 3, 4])
    thicknesses = args.thicknesses or ([0.01, 0.3] if args.quick else [0.01, 0.084, 0.3])
    resolution = args.resolution or (0.02 if args.quick else 0.002)
    os.makedirs(args.out, exist_ok=True)
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    result = {
        "benchmark": "stability",
        "date": date.today().isoformat(),
        **describe_device(device),
        "options": {**vars(args), "levels": levels, "shell_levels": shell_levels, "thicknesses": thicknesses},
        "quick": args.quick,
        "resolution": resolution,
        "criterion": (f"bisection on dt / predicted bound in [0.5, 2] to {resolution:g}; a trial is unstable when it "
                      "raises BlowUpError ('blow-up'), its OscillationError (FHN's period-2 flip detector, 'flip-flop') or "
                      "the watched deviation (max norm) grows past `growth` x its initial value ('growth') within `steps` "
                      f"steps (both per row), checked every {CHUNK}; `unstable_by` names what fired at the first unstable dt; "
                      f"initial data random in [0, {NOISE:g}] "
                      f"(FHN excited: 1 + that; dynamics: velocities, normal with deviation {args.velocity:g})"),
        "relax_note": ("Shell.relax is nonlinear CG with an Armijo line search: no time step, so no stability "
                       "bound; the rows report convergence (iterations to the default tolerance) instead"),
        "rows": [],
        "relax": [],
    }  # fmt: skip

    def report(row):
        result["rows"].append(row)
        save_json(args, device, result)
        what = {"telegraph": f"{row.get('discretization')} p={row.get('mass_corrections')}",
                "dynamics": f"h={row.get('thickness')}"}.get(row["method"], row.get("state"))  # fmt: skip
        print(f"{device.alias:7s} {row['method']:12s} {what:18s} L{row['level']} {row['vertices']:>6d} V {row['dtype']}: "
              f"predicted {row['predicted_dt']:.5g}  measured {row['measured_dt']:.5g}  ratio {row['ratio']:.4f}  "
              f"({row['trials']} trials, unstable by {row['unstable_by']}, {row['seconds']:.1f} s)", flush=True)  # fmt: skip

    def report_relax(r):
        result["relax"].append(r)
        save_json(args, device, result)
        print(f"{device.alias:7s} relax        h={r['thickness']:<16g} L{r['level']} {r['vertices']:>6d} V {r['dtype']}: "
              f"converged {r['converged']}, {r['iterations']} iterations, residual {r['final_residual']:.2g} "
              f"({r['seconds']:.1f} s)", flush=True)  # fmt: skip

    for dtype in args.dtypes:
        for level in levels:
            if "telegraph" in args.parts:
                for discretization, corrections in TELEGRAPH:
                    report(telegraph_row(level, discretization, corrections, dtype, device.alias, resolution))
            if "fhn" in args.parts:
                for state in ("rest", "excited"):
                    report(fhn_row(level, state, "explicit", dtype, device.alias, resolution))
                if level <= args.imex_max_level:
                    report(fhn_row(level, "excited", "imex", dtype, device.alias, resolution))
        for level in shell_levels if "dynamics" in args.parts else []:
            for thickness in thicknesses:
                report(dynamics_row(level, thickness, args.velocity, dtype, device.alias, resolution))
        for level in shell_levels if "relax" in args.parts else []:
            for thickness in thicknesses:
                report_relax(relax_row(level, thickness, dtype, device.alias))
    json_path = save_json(args, device, result)
    png_path = os.path.splitext(json_path)[0] + ".png"
    chart(result, png_path)
    print(f"wrote {json_path} and {png_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
