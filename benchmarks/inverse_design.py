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
sensitive parameter moves by `--rate` of itself; `--points` adds the rest shape's control points, whose
coordinates step by `--rate` of the control points' RMS radius L at most (scaled by L dJ/dX). A step
that does not raise J (read from the next batch's unperturbed world) is undone and the rate halved. Writes
inverse_design.json after every iteration (θ, J, the gradient, the rate, accepted or not; at the end the
verifying run and the best rest shape) and .png (J against iteration, θ).
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace
from datetime import date

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from wavewarp.adjoint import walker_adjoint_gradient  # noqa: E402
from wavewarp.device import describe_device, resolve_device  # noqa: E402
from wavewarp.driver import simulate  # noqa: E402
from wavewarp.io import write_png, write_result  # noqa: E402
from wavewarp.mesh import Mesh  # noqa: E402
from wavewarp.parameters import load_scene, resolve  # noqa: E402
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


def ascend(objective_and_gradient, theta: dict, *, iterations: int, rate: float, lengths=None, report=print,
           on_iteration=None) -> list:  # fmt: skip
    """Trust-region ascent in log θ (`lengths`: additive coordinates, `log_step`'s). `objective_and_gradient(θ)`
    -> (J, {name: dJ/dθ}). Returns the history, one row per evaluation: θ, J, gradient, the rate the next step
    used, and whether θ was accepted (J rose); `on_iteration(history)` after each."""
    history, best = [], None
    for iteration in range(iterations):
        value, gradient = objective_and_gradient(theta)
        accepted = best is None or value > best["J"]
        if accepted:
            best = {"theta": theta, "J": value, "gradient": gradient}
        else:
            rate /= 2.0
        history.append({"iteration": iteration, "theta": theta, "J": value, "gradient": gradient, "rate": rate,
                        "accepted": accepted})  # fmt: skip
        report(f"iteration {iteration}: J = {value:+.6g} R ({'accepted' if accepted else 'undone'})")
        if on_iteration is not None:
            on_iteration(history)
        theta = log_step(best["theta"], best["gradient"], rate, lengths)
    return history


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
    parser.add_argument("--method", default="differences", choices=("differences", "adjoint"),
                        help="the gradient: central differences over one batch, or the reverse mode (the rest shape "
                        "with a chemistry step given)")  # fmt: skip
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="fixed scene parameters")
    parser.add_argument("--device", default=None)
    parser.add_argument("--quick", action="store_true", help="the scene's quick mesh (a CPU smoke run)")
    parser.add_argument("--out", default=".")
    args = parser.parse_args(argv)
    device = resolve_device(args.device)
    module = load_scene(args.scene)
    p = resolve(module.Parameters, getattr(module, "QUICK", {}) if args.quick else None,
                [*args.set, f"periods={args.periods}", "frames=1", "dtype=float64"])  # fmt: skip
    mesh = module.recipe(p, device=device, report=lambda message: None)[0]
    points = control_points(args.points, mesh.n_vertices)
    coordinates = {f"X{i}{axis}": (i, a) for i in points for a, axis in enumerate("xyz")}  # θ's shape names

    def rest_shape(theta) -> np.ndarray:
        displacement = np.zeros_like(mesh.vertices)
        for name, (i, a) in coordinates.items():
            displacement[i, a] = theta[name]
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
        shape = {name: float(result["shape_gradient"][points.index(i), a]) for name, (i, a) in coordinates.items()}
        return result["objective"], {**result["gradient"], **shape}

    header = {"benchmark": "inverse_design", "date": date.today().isoformat(), **describe_device(device),
              "scene": args.scene, "quick": args.quick, "periods": args.periods, "wrt": args.wrt, "points": points,
              "method": args.method, "step": args.step, "set": args.set, "length": control_scale(mesh.vertices)}  # fmt: skip

    def durable(history):  # every iteration written: a cut run keeps what it did
        write_result({**header, "history": history}, args.out, "inverse_design", chart)

    theta = {**{name: float(getattr(p, name)) for name in args.wrt}, **{name: 0.0 for name in coordinates}}
    lengths = {name: header["length"] for name in coordinates}
    history = ascend(objective_and_gradient, theta, iterations=args.iterations, rate=args.rate, lengths=lengths,
                     on_iteration=durable)  # fmt: skip
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
