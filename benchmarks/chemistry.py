"""Chemistry benchmark (issue 4): wave steps per second, and eigenvalue accuracy against cost.

    python benchmarks/chemistry.py --device cpu --out benchmarks/results [--quick]

Throughput: telegraph leapfrog steps per second (γ = R = 1, dt = 0.9 × the stability bound)
on level-L icospheres, for the subdivision operator with lumped mass (p = 0), with two mass
corrections (p = 2), and for P1; float32 and float64; assembled K (default) and, in float32,
matrix-free K. FitzHugh–Nagumo (the paper's ν, κ, ε, γ = 1),
float32: explicit Euler at 0.9 × its bound, IMEX at dt = 0.05 (CG to 1e-5). Each figure is the median of 3 timed runs
after a warm-up (graph capture), each run long enough to take `--min-seconds`; the device is
synchronised by the blow-up check at the end of every `advance`.

Accuracy: the largest relative error of the 48 sphere eigenvalues l = 1..6 (exact l(l+1)) of
the operators the steppers use (M⁻¹K lumped, W_2 K corrected, P1) and of the Galerkin pencils
(K, consistent mass), each with the wall time of its eigensolve (operator build, assembly and
scipy; shift-invert eigsh, LOBPCG for W_2 K). Writes chemistry_<device>.json and the chart
chemistry_<device>.png (error against seconds per simulated time unit, and against eigensolve
time).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import time
import warnings
from datetime import date

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import warp as wp

from wavewarp.device import describe_device, device_tag, resolve_device
from wavewarp.io import write_json, write_png
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.initial import gaussian_pulse
from wavewarp.waves import FitzHughNagumo, Telegraph

EXACT = np.concatenate([[l * (l + 1)] * (2 * l + 1) for l in range(7)])
STEPPERS = (("subdivision", 0), ("subdivision", 2), ("p1", 0))  # telegraph: (discretization, mass corrections)
WAVES = ("telegraph", "fhn-explicit", "fhn-imex")
IMEX_DT = 0.05  # γ = R = 1: 60 steps per pole-to-pole crossing
LABELS = {
    ("subdivision", 0): "subdivision, lumped mass",
    ("subdivision", 2): "subdivision, 2 mass corrections",
    ("p1", 0): "P1 cotangent, lumped mass",
    ("subdivision", "consistent"): "subdivision Galerkin (consistent mass)",
    ("p1", "consistent"): "P1 consistent mass",
}


@functools.lru_cache(maxsize=None)
def sphere(level):
    """The unit icosphere of one level, built once per run (the host-side build dominates on a GPU)."""
    return icosphere(1.0, level)


def make_wave(wave, op, c0, v0, corrections):
    """The stepper of one throughput row (γ = R = 1; FHN with the paper's ν, κ, ε)."""
    if wave == "telegraph":
        return Telegraph(op, 1.0, 0.001, c0=c0, v0=v0, mass_corrections=corrections, check_every=20)
    if wave == "fhn-explicit":
        return FitzHughNagumo(op, 1.0, c0=c0, check_every=20)
    return FitzHughNagumo(op, 1.0, c0=c0, dt=IMEX_DT, scheme="imex", check_every=20)


def throughput(wave_kind, level, discretization, corrections, dtype, assembled, device, min_seconds) -> dict:
    mesh = sphere(level)
    start = time.perf_counter()
    op = LaplaceBeltrami(mesh, discretization=discretization, assembled=assembled, device=device, dtype=dtype)
    c0, v0 = gaussian_pulse(op, 0, 0.3, gamma=1.0)
    build = time.perf_counter() - start
    start = time.perf_counter()
    wave = make_wave(wave_kind, op, c0, v0, corrections)
    guard = time.perf_counter() - start
    wave.advance(wave.check_every)  # graph capture and warm-up
    steps = wave.check_every
    while True:
        start = time.perf_counter()
        wave.advance(steps)
        if time.perf_counter() - start >= min_seconds:
            break
        steps *= 2
    timings = [time.perf_counter() - start]
    for _ in range(2):
        start = time.perf_counter()
        wave.advance(steps)
        timings.append(time.perf_counter() - start)
    rate = steps / float(np.median(timings))
    return {
        "wave": wave_kind, "assembled": assembled, "level": level, "vertices": mesh.n_vertices, "discretization": discretization, "mass_corrections": corrections,
        "dtype": dtype, "steps_per_second": rate, "dt": wave.dt, "stable_dt": wave.stable_dt,
        "seconds_per_unit_time": 1.0 / (rate * wave.dt), "build_seconds": build, "guard_seconds": guard,
    }  # fmt: skip


def spectrum_error(values) -> float:
    values = np.sort(values)
    return float(np.max(np.abs(values[1:] - EXACT[1:]) / EXACT[1:]))


def galerkin_spectrum(level, discretization, mass, device) -> dict:
    start = time.perf_counter()
    op = LaplaceBeltrami(sphere(level), discretization=discretization, device=device, dtype="float64")
    K = op.stiffness_matrix()
    M = sp.diags(op.mass()) if mass == "lumped" else op.mass_matrix()
    v0 = np.random.default_rng(1).uniform(0.5, 1.5, op.n_vertices)  # 64 requested, 49 kept: ARPACK can drop
    values = np.sort(sla.eigsh(K, k=64, M=M, sigma=-0.1, v0=v0, return_eigenvectors=False))[:49]  # a degenerate copy
    return {"level": level, "vertices": op.n_vertices, "discretization": discretization, "mass": mass,
            "error": spectrum_error(values), "seconds": time.perf_counter() - start}  # fmt: skip


def corrected_spectrum(level, corrections, device) -> dict:
    """Eigenvalues of W_p K through the symmetric pencil (W K W, W) in ψ = W⁻¹φ, by LOBPCG
    preconditioned with M_c (K + M_c)⁻¹ M_c, started from the Galerkin eigenvectors."""
    start = time.perf_counter()
    op = LaplaceBeltrami(sphere(level), device=device, dtype="float64")
    K, Mc = op.stiffness_matrix(), op.mass_matrix()
    G = sp.diags(1.0 / op.mass())

    def W(X):
        result = term = G @ X
        for _ in range(corrections):
            term = term - G @ (Mc @ term)
            result = result + term
        return result

    n = op.n_vertices
    A = sla.LinearOperator((n, n), matvec=lambda x: W(K @ W(x)), matmat=lambda X: W(K @ W(X)), dtype=float)
    B = sla.LinearOperator((n, n), matvec=W, matmat=W, dtype=float)
    lu = sla.splu((K + Mc).tocsc())
    T = sla.LinearOperator((n, n), matvec=lambda x: Mc @ lu.solve(Mc @ x), matmat=lambda X: Mc @ lu.solve(np.asarray(Mc @ X)),
                           dtype=float)  # fmt: skip
    values, vectors = sla.eigsh(K, k=64, M=Mc, sigma=-0.1, v0=np.random.default_rng(1).uniform(0.5, 1.5, n))
    vectors = vectors[:, np.argsort(values)[:49]]
    guess = Mc @ vectors + 1e-3 * np.random.default_rng(0).normal(size=vectors.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # LOBPCG reports residuals ~1e-8 as "not reaching 1e-10"
        values, _ = sla.lobpcg(A, guess, B=B, M=T, largest=False, tol=1e-10, maxiter=150)
    return {"level": level, "vertices": n, "discretization": "subdivision", "mass": f"W_{corrections}",
            "error": spectrum_error(values), "seconds": time.perf_counter() - start}  # fmt: skip


def orders(rows, key_fields) -> dict:
    """Convergence order log2(e_L / e_{L+1}) between consecutive levels, per configuration."""
    out = {}
    for key in sorted({tuple(r[k] for k in key_fields) for r in rows}, key=str):
        series = sorted((r["level"], r["error"]) for r in rows if tuple(r[k] for k in key_fields) == key)
        out["/".join(map(str, key))] = {f"{a}->{b}": float(np.log2(ea / eb)) for (a, ea), (b, eb) in zip(series, series[1:])}
    return out


def chart(result, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 5))
    by_level = {(r["discretization"], r["mass"], r["level"]): r for r in result["spectrum"]}
    for discretization, corrections in STEPPERS:
        mass = "lumped" if corrections == 0 else f"W_{corrections}"
        points = [(row["seconds_per_unit_time"], by_level[discretization, mass, row["level"]]["error"], row["level"])
                  for row in result["throughput"]
                  if row["wave"] == "telegraph" and row["assembled"] and row["dtype"] == "float32"
                  and row["discretization"] == discretization
                  and row["mass_corrections"] == corrections and (discretization, mass, row["level"]) in by_level]  # fmt: skip
        if points:
            x, y, levels = zip(*points)
            left.loglog(x, y, "o-", label=LABELS[discretization, corrections])
            for xi, yi, level in points:
                left.annotate(f"L{level}", (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=8)
    left.set_xlabel("wall seconds per simulated time unit (telegraph, γ = R = 1, float32)")
    left.set_ylabel("max relative eigenvalue error, l ≤ 6")
    left.set_title("accuracy of the wave operator against stepping cost")
    left.legend(fontsize=8)
    for discretization, mass in (("subdivision", "lumped"), ("subdivision", "consistent"), ("p1", "lumped"),
                                 ("p1", "consistent")):  # one solver (shift-invert eigsh) for all  # fmt: skip
        rows = sorted((r for r in result["spectrum"] if r["discretization"] == discretization and r["mass"] == mass),
                      key=lambda r: r["level"])  # fmt: skip
        if rows:
            label = {"lumped": "lumped mass", "consistent": "consistent mass (Galerkin)"}[mass]
            right.loglog([r["seconds"] for r in rows], [r["error"] for r in rows], "o-", label=f"{discretization}, {label}")
    right.set_xlabel("eigensolve wall time, s (build + assembly + scipy, float64, host)")
    right.set_ylabel("max relative eigenvalue error, l ≤ 6")
    right.set_title("sphere spectrum l(l+1): accuracy against eigensolve time")
    right.legend(fontsize=8)
    fig.suptitle(f"wavewarp chemistry, {result['device_name']} ({result['date']})")
    fig.tight_layout()
    write_png(fig, path)


def save_json(args, device, result) -> str:
    """Write the result (also after every throughput row, so an interrupted run keeps its rows)."""
    name = f"chemistry_{device_tag(device)}{'_quick' if args.quick else ''}"
    path = os.path.join(args.out, name + ".json")
    write_json(path, result)
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench chemistry", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", default="benchmarks/results")
    parser.add_argument("--quick", action="store_true", help="levels 3-4 and spectra at levels 2-3 (a smoke test)")
    parser.add_argument("--levels", type=int, nargs="+", default=None, help="throughput levels (default 3 4 5 6 7)")
    parser.add_argument("--spectrum-levels", type=int, nargs="+", default=None, help="default 2 3 4 5 6")
    parser.add_argument("--corrected-spectrum-max-level", type=int, default=5, help="W_2 spectra (LOBPCG) up to here")
    parser.add_argument("--min-seconds", type=float, default=None, help="shortest timed run (default 2, quick 0.3)")
    parser.add_argument("--waves", nargs="+", choices=WAVES, default=list(WAVES), help="steppers to time (default: all)")
    parser.add_argument("--spectrum-from", default=None,
                        help="reuse the spectra of an earlier result JSON (host float64 eigensolves: device-independent)")
    args = parser.parse_args(argv)
    levels = args.levels or ([3, 4] if args.quick else [3, 4, 5, 6, 7])
    spectrum_levels = args.spectrum_levels or ([2, 3] if args.quick else [2, 3, 4, 5, 6])
    min_seconds = args.min_seconds or (0.3 if args.quick else 2.0)
    os.makedirs(args.out, exist_ok=True)
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)

    configurations = [("telegraph", d, p, dtype, True) for d, p in STEPPERS for dtype in ("float32", "float64")]
    configurations += [("telegraph", d, 0, "float32", False) for d in ("subdivision", "p1")]  # matrix-free K
    configurations += [(w, d, 0, "float32", True) for w in WAVES[1:] for d in ("subdivision", "p1")]
    rows = []
    for level in levels:
        for wave, discretization, corrections, dtype, assembled in configurations:
            if wave in args.waves:
                row = throughput(wave, level, discretization, corrections, dtype, assembled, device.alias, min_seconds)
                rows.append(row)
                save_json(args, device, {"benchmark": "chemistry", "partial": True, "throughput": rows})
                kind = "assembled" if assembled else "matrix-free"
                print(f"{device.alias:7s} L{level} {row['vertices']:>7d} V {wave:12s} {discretization:11s} {kind:11s} p={corrections} {dtype}: "
                      f"{row['steps_per_second']:10.1f} steps/s  dt {row['dt']:.3g}  "
                      f"{row['seconds_per_unit_time']:.3g} s per time unit  (guard {row['guard_seconds']:.2f} s)", flush=True)  # fmt: skip
    spectra = []
    if args.spectrum_from:
        with open(args.spectrum_from) as f:
            earlier = json.load(f)
        spectra = earlier["spectrum"]
        spectrum_levels = sorted({r["level"] for r in spectra})
        print(f"spectra from {args.spectrum_from} ({earlier['device_name']}, {earlier['date']})")
    for level in [] if args.spectrum_from else spectrum_levels:
        for discretization in ("subdivision", "p1"):
            for mass in ("lumped", "consistent"):
                spectra.append(galerkin_spectrum(level, discretization, mass, device.alias))
                r = spectra[-1]
                print(f"spectrum L{level} {discretization:11s} {mass:10s}: max rel error {r['error']:.3e}  ({r['seconds']:.2f} s)", flush=True)
        if level <= args.corrected_spectrum_max_level:
            spectra.append(corrected_spectrum(level, 2, device.alias))
            r = spectra[-1]
            print(f"spectrum L{level} subdivision W_2       : max rel error {r['error']:.3e}  ({r['seconds']:.2f} s)", flush=True)
    result = {
        "benchmark": "chemistry",
        "date": date.today().isoformat(),
        **describe_device(device),
        "throughput": rows,
        "spectrum": spectra,
        "spectrum_source": args.spectrum_from or "this run",
        "spectrum_orders": orders(spectra, ("discretization", "mass")),
    }
    error = {(r["discretization"], r["mass"], r["level"]): r["error"] for r in spectra}
    result["p1_over_subdivision_error"] = {
        f"level {level}": {mass: error["p1", "lumped", level] / error["subdivision", mass, level]
                           for mass in ("lumped", "consistent", "W_2") if ("subdivision", mass, level) in error}
        for level in spectrum_levels
    }  # fmt: skip
    print("spectrum orders:", json.dumps(result["spectrum_orders"], indent=1))
    print("P1 (lumped) error / subdivision error:", json.dumps(result["p1_over_subdivision_error"], indent=1))
    json_path = save_json(args, device, result)
    png_path = os.path.splitext(json_path)[0] + ".png"
    chart(result, png_path)
    print(f"wrote {json_path} and {png_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
