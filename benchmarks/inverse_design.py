"""Inverse design of a walker (issue 31): raise the walk over a horizon by gradient steps on shell
parameters, the gradient by central differences over one batch (wavewarp/walker_gradients.py) or by the
reverse mode (`--method adjoint`, wavewarp/adjoint.py: the overdamped walkers with either wave, the rest shape's
control points too), and verify the result by a plain forward run of the scene.

    wavewarp bench inverse_design --scene prism-walker --wrt AC thickness elongation --periods 1 --iterations 8 \\
        --device cuda --out benchmarks/results/inverse_design
    wavewarp bench inverse_design --scene prism-walker --quick --wrt AC thickness --points all --device cuda
    wavewarp bench inverse_design --scene sphere-walker --method adjoint --wrt AC thickness young friction \
        --set sensitive=false --set contact_solve=explicit --set sharpness=0.1 --set level=2 --device cpu
    wavewarp bench inverse_design --scene prism-walker --quick --method adjoint --wrt AC thickness elongation \
        --points all --set dt=0.5 --device cpu

The steps are taken in log θ (every parameter stays positive) within a trust region: the most
sensitive parameter moves by `--rate` of itself; `--points` adds the rest shape's control points, which
step along the shape's ascent direction d, dJ/dX smoothed over a length ℓ (`--smoothing`, in the control
points' RMS radius L, and no shorter than the control mesh's mean edge, which no displacement of its points
varies over less; `shape_smoother`), by `--rate` × ℓ at most (scaled by ℓ d): a displacement that
varies over ℓ and stretches the rest mesh's edges by about `--rate` at most. (Unsmoothed, one control point of
a fine mesh would move alone by as much, the mesh would fold and the mechanics' stable step collapse.) A step
that does not raise J (read from the next batch's unperturbed world) is undone and the rate halved. Writes
inverse_design.json after every iteration (θ, J, the gradient, the rate, accepted or not, seconds; at the end the
verifying run and the best rest shape) and .png (J against iteration, θ). `--resume` goes on from the
inverse_design.json in `--out` (the same settings) until `--iterations` evaluations are done: a run cut by a time
limit is run again, with `--resume`, and takes the steps it would have taken.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import replace
from datetime import date

import numpy as np
from scipy.sparse.linalg import factorized

if __package__ in (None, ""):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from wavewarp.adjoint import walker_adjoint_gradient  # noqa: E402
from wavewarp.device import describe_device, resolve_device  # noqa: E402
from wavewarp.driver import simulate  # noqa: E402
from wavewarp.io import write_png, write_result  # noqa: E402
from wavewarp.laplace import LaplaceBeltrami  # noqa: E402
from wavewarp.mesh import Mesh  # noqa: E402
from wavewarp.parameters import load_scene, resolve  # noqa: E402
from wavewarp.runs import mean_edge  # noqa: E402
from wavewarp.gradients import control_points, control_scale  # noqa: E402
from wavewarp.walker_gradients import walker_gradient  # noqa: E402


def log_step(theta: dict, gradient: dict, rate: float, lengths=None) -> dict:
    """θ after one ascent step in log θ: Δ ln θ_k = rate × (θ_k g_k) / max_j |s_j| with s_k = θ_k g_k (the most
    sensitive parameter changes by the factor e^±rate); the names in `lengths` (name -> L, coordinates that may
    be any sign) step additively, Δθ_k = rate × L s_k / max_j |s_j| with s_k = L g_k."""
    lengths = lengths or {}
    scaled = {name: (lengths[name] if name in lengths else theta[name]) * gradient[name] for name in theta}
    largest = max(abs(value) for value in scaled.values()) or 1.0
    return {name: theta[name] + rate * lengths[name] * scaled[name] / largest if name in lengths
            else theta[name] * float(np.exp(rate * scaled[name] / largest)) for name in theta}  # fmt: skip


def shape_smoother(mesh: Mesh, points: list, length: float):
    """g -> d: the rest shape's ascent direction d (len(points), 3) for dJ/dX g of the control `points` of `mesh`, the
    gradient in the H¹ metric of the displacement u = Σ N_I ΔX_I (I in `points`) on the limit surface,
    ∫ u·u + ℓ² ∇u:∇u dω̄ = ΔXᵀ B ΔX, B = M + ℓ²K (the subdivision basis' consistent mass and stiffness): d = B⁻¹ g
    per axis (B's rows and columns of `points`, factorised once), times the area a control point carries on average.
    dJ = g·d > 0 for any g; g of a uniform J density on every point, g = M f (f constant), gives d = f × the mean area
    (K f = 0), g itself where the points carry equal areas; unlike g, d does not grow finer with the mesh: one point's
    spike of g spreads over ℓ instead of moving that point alone."""
    operator = LaplaceBeltrami(mesh, device="cpu", dtype="float64")
    mass = operator.mass_matrix()
    solve = factorized((mass + length**2 * operator.stiffness_matrix()).tocsr()[points][:, points].tocsc())
    carried = mass.sum() / mesh.n_vertices
    return lambda gradient: np.column_stack([solve(gradient[:, axis]) for axis in range(3)]) * carried


def ascend(objective_and_gradient, theta: dict, *, iterations: int, rate: float, lengths=None, report=print,
           on_iteration=None, history=(), direction=None) -> list:  # fmt: skip
    """Trust-region ascent in log θ (`lengths`: additive coordinates, `log_step`'s). `objective_and_gradient(θ)`
    -> (J, {name: dJ/dθ}); `direction(gradient)`, where given, the step's direction in its place (the same names).
    Returns the history, one row per evaluation: θ, J, gradient, the rate the next step used, whether θ was
    accepted (J rose) and the evaluation's seconds; `on_iteration(history)` after each. A `history` given (an
    earlier run's rows) is gone on from: the step after its last row, up to `iterations` rows."""
    direction = direction or (lambda gradient: gradient)
    history, best = list(history), None
    for row in history:
        if row["accepted"]:
            best = row
    rate = history[-1]["rate"] if history else rate
    for iteration in range(len(history), iterations):
        if history:  # the step from the best θ so far
            theta = log_step(best["theta"], direction(best["gradient"]), rate, lengths)
        started = time.perf_counter()
        value, gradient = objective_and_gradient(theta)
        accepted = bool(best is None or value > best["J"])
        if accepted:
            best = {"theta": theta, "J": value, "gradient": gradient}
        else:
            rate /= 2.0
        history.append({"iteration": iteration, "theta": theta, "J": value, "gradient": gradient, "rate": rate,
                        "accepted": accepted, "seconds": time.perf_counter() - started})  # fmt: skip
        report(f"iteration {iteration}: J = {value:+.6g} R ({'accepted' if accepted else 'undone'}, "
               f"{history[-1]['seconds']:.1f} s)")  # fmt: skip
        if on_iteration is not None:
            on_iteration(history)
    return history


def earlier_history(path: str, header: dict) -> list:
    """The rows of the run written at `path` (inverse_design.json) with the same settings as `header`."""
    if not os.path.exists(path):
        raise SystemExit(f"--resume: there is no {path} to go on from; run without --resume first")
    with open(path) as f:
        earlier = json.load(f)
    same = ("scene", "quick", "periods", "wrt", "points", "method", "step", "set", "length", "smoothing")

    def equal(a, b):  # the length is recomputed from the mesh: to round-off
        return math.isclose(a, b, rel_tol=1e-12) if isinstance(a, float) and isinstance(b, float) else a == b

    differing = [key for key in same if not equal(earlier.get(key), header[key])]
    if differing:
        values = ", ".join(repr(earlier.get(key)) for key in differing)
        raise SystemExit(f"--resume: {path} was run with other settings ({', '.join(differing)}: {values}); give the "
                         "same ones or another --out")  # fmt: skip
    return earlier["history"]


def verify(module, p, device, mesh=None) -> float:
    """The walk of a plain forward run of the scene at `p` (its own steps; `mesh`: the scene's control mesh
    replaced): J at its end, in R."""
    outcome = simulate(module.build(p, mesh=mesh, device=device, report=lambda message: None), [])
    if outcome.failure is not None:
        raise RuntimeError(f"the verifying forward run stopped: {outcome.failure}")
    return float(outcome.measurements["distance_R"])


def chart(result: dict, path: str) -> None:
    import matplotlib.pyplot as plt

    history = result["history"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    iterations = [row["iteration"] for row in history]
    left.plot(iterations, [row["J"] for row in history], "o-", color="k")
    for row in history:
        if not row["accepted"]:
            left.plot(row["iteration"], row["J"], "x", color="tab:red", ms=9)
    if "verified_J" in result:
        left.axhline(result["verified_J"], color="tab:green", ls="--", label="plain forward run at the best θ")
        left.legend(fontsize=8)
    left.set_xlabel("iteration")
    left.set_ylabel(f"J: displacement along the wave after {result['periods']:g} T₀ (R)")
    for name in result["wrt"]:
        start = history[0]["theta"][name]
        right.plot(iterations, [row["theta"][name] / start for row in history], "o-", label=f"{name} / {start:g}")
    shape = [name for name in history[0]["theta"] if name not in result["wrt"]]
    if shape:
        moved = [np.sqrt(np.mean([row["theta"][name] ** 2 for name in shape])) / result["length"] for row in history]
        right.plot(iterations, moved, "s-", label="control points: RMS displacement / L")
    right.set_xlabel("iteration")
    right.set_ylabel("θ / θ₀; displacement / L")
    right.legend(fontsize=8)
    fig.suptitle(f"{result['scene']}: gradient ascent of the walk, {result['device_name']}", fontsize=10)
    fig.tight_layout()
    write_png(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench inverse_design", description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="prism-walker")
    parser.add_argument("--wrt", nargs="*", default=["AC", "thickness", "elongation"],
                        help="per-world parameters (elongation: the rest shape stretched along the wave)")
    parser.add_argument("--points", default=(), metavar="I[,I...]|all", help="the rest shape's control points designed too",
                        type=lambda text: text if text == "all" else [int(i) for i in text.split(",")])  # fmt: skip
    parser.add_argument("--periods", type=float, default=1.0, help="the horizon, in periods of the FHN kinetics")
    parser.add_argument("--iterations", type=int, default=8)
    parser.add_argument("--rate", type=float, default=0.2, help="the first step: the most sensitive θ moves by e^rate")
    parser.add_argument("--step", type=float, default=1e-4, help="relative step of the central differences")
    parser.add_argument("--smoothing", type=float, default=0.2, metavar="ℓ/L",
                        help="the rest shape's steps smoothed over ℓ and at most rate × ℓ, ℓ in the control points' "
                        "RMS radius L (the control mesh's mean edge at least)")  # fmt: skip
    parser.add_argument("--method", default="differences", choices=("differences", "adjoint"),
                        help="the gradient: central differences over one batch, or the reverse mode (the rest shape "
                        "with a chemistry step given)")  # fmt: skip
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="fixed scene parameters")
    parser.add_argument("--device", default=None)
    parser.add_argument("--quick", action="store_true", help="the scene's quick mesh (a CPU smoke run)")
    parser.add_argument("--out", default=".")
    parser.add_argument("--resume", action="store_true",
                        help="go on from OUT/inverse_design.json (a run cut short, or more --iterations)")
    args = parser.parse_args(argv)
    if not args.smoothing > 0.0:
        parser.error(f"--smoothing {args.smoothing}: give a length > 0 (in the control points' RMS radius; 0.2 is "
                     "the default)")  # fmt: skip
    device = resolve_device(args.device)
    module = load_scene(args.scene)
    p = resolve(module.Parameters, getattr(module, "QUICK", {}) if args.quick else None,
                [*args.set, f"periods={args.periods}", "frames=1", "dtype=float64"])  # fmt: skip
    mesh = module.recipe(p, device=device, report=lambda message: None)[0]
    points = control_points(args.points, mesh.n_vertices)
    coordinates = {f"X{i}{axis}": (row, a) for row, i in enumerate(points) for a, axis in enumerate("xyz")}

    def rest_shape(theta) -> np.ndarray:
        displacement = np.zeros_like(mesh.vertices)
        for name, (row, a) in coordinates.items():
            displacement[points[row], a] = theta[name]
        return displacement

    def objective_and_gradient(theta):
        parameters = {name: theta[name] for name in args.wrt}
        if args.method == "adjoint":
            shaped = Mesh(mesh.vertices + rest_shape(theta), mesh.triangles) if points else None
            result = walker_adjoint_gradient(module, replace(p, **parameters), args.wrt, points=points, mesh=shaped,
                                             device=device, report=lambda message: None)  # fmt: skip
        else:
            result = walker_gradient(module, replace(p, **parameters), args.wrt, points=points, device=device,
                                     rest_shape=rest_shape(theta), steps=(args.step,),
                                     report=lambda message: None)  # fmt: skip
        shape = {name: float(result["shape_gradient"][row, a]) for name, (row, a) in coordinates.items()}
        return result["objective"], {**result["gradient"], **shape}

    header = {"benchmark": "inverse_design", "date": date.today().isoformat(), **describe_device(device),
              "scene": args.scene, "quick": args.quick, "periods": args.periods, "wrt": args.wrt, "points": points,
              "method": args.method, "step": args.step, "set": args.set, "length": control_scale(mesh.vertices),
              "smoothing": args.smoothing}  # fmt: skip

    def durable(history):  # every iteration written: a cut run keeps what it did
        write_result({**header, "history": history}, args.out, "inverse_design", chart)

    earlier = earlier_history(os.path.join(args.out, "inverse_design.json"), header) if args.resume else ()
    theta = {**{name: float(getattr(p, name)) for name in args.wrt}, **{name: 0.0 for name in coordinates}}
    smoothing = max(args.smoothing * header["length"], mean_edge(mesh))  # ℓ
    lengths = {name: smoothing for name in coordinates}

    smooth = shape_smoother(mesh, points, smoothing) if points else None  # on the scene's rest shape

    def direction(gradient):  # the shape's coordinates smoothed over ℓ
        if smooth is None:
            return gradient
        by_point = np.zeros((len(points), 3))
        for name, (row, a) in coordinates.items():
            by_point[row, a] = gradient[name]
        smoothed = smooth(by_point)
        return {**gradient, **{name: float(smoothed[row, a]) for name, (row, a) in coordinates.items()}}

    history = ascend(objective_and_gradient, theta, iterations=args.iterations, rate=args.rate, lengths=lengths,
                     on_iteration=durable, history=earlier, direction=direction)  # fmt: skip
    best = max((row for row in history if row["accepted"]), key=lambda row: row["J"])
    designed = Mesh(mesh.vertices + rest_shape(best["theta"]), mesh.triangles)
    verified = verify(module, replace(p, **{name: best["theta"][name] for name in args.wrt}), device,
                      designed if points else None)  # fmt: skip
    print(f"best J = {best['J']:+.6g} R (from {history[0]['J']:+.6g}); plain forward run: {verified:+.6g} R")
    write_result({**header, "history": history, "best": best, "verified_J": verified,
                  "best_rest_vertices": designed.vertices.tolist() if points else None},
                 args.out, "inverse_design", chart)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
