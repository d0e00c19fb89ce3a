"""How far a walker's gradient reaches (issue 31, chaos): dJ/dθ of the walk J(t) (the centre of mass's
displacement along the wave, R) against the horizon t, by central differences with steps from 1e-2 to
1e-6 of θ (`--wrt`, default AC) over one float64 batch per scene and mechanics
(wavewarp/walker_gradients.py).

    wavewarp bench gradient_horizon --device cuda --periods 6 --out benchmarks/results/gradient_horizon

Per run: the derivative's running magnitude max_{s≤t} |g(s)| (floored at 1% of the run's largest) and its
growth per period (up to the converged horizon); the *useful
horizon*, the first time the largest step's difference departs from the smallest step's derivative by
more than 10% of that magnitude (beyond it a step of 1% of θ is no longer linear); and the
*converged horizon*, the same for the two smallest steps at 1e-3 (beyond it the derivative itself is
not resolved: chaos at the scale of round-off). Writes gradient_horizon.json and .png.
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

from wavewarp.device import describe_device, resolve_device  # noqa: E402
from wavewarp.io import write_png, write_result  # noqa: E402
from wavewarp.parameters import load_scene, resolve  # noqa: E402
from wavewarp.walker_gradients import AGREEMENT, PER_WORLD, walker_gradient  # noqa: E402

SCENES = ("sphere-walker", "prism-walker")
MECHANICS = {"default": [], "inertial": ["mechanics=inertial", "contact_solve=explicit", "sharpness=0.1"]}
STEPS = (1e-2, 1e-4, 1e-6)
USEFUL = 0.1  # the departure (relative to the running magnitude) that ends the useful horizon; AGREEMENT the converged
FLOOR = 0.01  # the running magnitude's floor, a share of the run's largest |dJ/dθ|


def running_magnitude(series: np.ndarray) -> np.ndarray:
    """max_{s≤t} |g(s)|, floored at the smallest positive value (a derivative that starts at 0)."""
    magnitude = np.maximum.accumulate(np.abs(series))
    positive = magnitude[magnitude > 0]
    return np.maximum(magnitude, positive.min() if positive.size else 1e-300)


def horizon(times: np.ndarray, reference: np.ndarray, other: np.ndarray, tolerance: float):
    """The first time |other - reference| exceeds `tolerance` × the running magnitude of reference, that magnitude
    floored at FLOOR of its largest over the run (the derivative's first rise from 0 is not a horizon); None: never."""
    scale = np.maximum(running_magnitude(reference), FLOOR * np.abs(reference).max())
    departed = np.abs(other - reference) > tolerance * scale
    return float(times[np.argmax(departed)]) if departed.any() else None


def growth_per_period(t_over_T: np.ndarray, series: np.ndarray, until: float | None = None) -> float | None:
    """The least-squares slope of log running |g| against t/T over the second half of [0, until] (default the
    whole run): e-folds a period; None where that is shorter than one period (the derivative's first rise
    from 0, not a growth)."""
    end = t_over_T[-1] if until is None else until
    if end < 1.0:
        return None
    half = (t_over_T >= end / 2) & (t_over_T <= end)
    return float(np.polyfit(t_over_T[half], np.log(running_magnitude(series)[half]), 1)[0])


def measure(scene: str, mechanics: str, args, device) -> dict:
    """One scene and mechanics: the derivative in `args.wrt` against the horizon for every step."""
    module = load_scene(scene)
    p = resolve(module.Parameters, getattr(module, "QUICK", {}) if args.quick else None,
                [*MECHANICS[mechanics], f"periods={args.periods}", f"sensitive={args.sensitive}", *args.set])  # fmt: skip
    p = replace(p, frames=max(1, round(args.periods)))
    result = walker_gradient(module, p, [args.wrt], steps=args.steps, device=device, report=lambda m: None)
    t = result["times"] / (result["period"] or result["period_kinetic"])  # the measured period, else the kinetics'
    series = result["derivatives"][args.wrt]
    smallest, second, largest = series[-1], series[-2] if len(series) > 1 else series[-1], series[0]
    useful, converged = horizon(t, smallest, largest, USEFUL), horizon(t, smallest, second, AGREEMENT)
    stride = max(1, len(t) // 400)  # the chart's and the JSON's samples
    label = " ".join([mechanics, *args.set, *(["insensitive"] if args.sensitive == "false" else [])])
    return {"scene": scene, "mechanics": mechanics, "label": label, "wrt": args.wrt, "value": getattr(p, args.wrt),
            "period": result["period"], "distance_R": result["objective"], "gradient_end": result["gradient"][args.wrt], "steps": list(args.steps), "useful_horizon_T": useful,
            "converged_horizon_T": converged, "growth_per_period": growth_per_period(t, smallest, converged),
            "t_over_T": t[::stride].tolist(), "derivatives": [s[::stride].tolist() for s in series],
            "distance": result["distance"][::stride].tolist()}  # fmt: skip


def chart(result: dict, path: str) -> None:
    import matplotlib.pyplot as plt
    from matplotlib import colormaps

    runs = result["runs"]
    fig, axes = plt.subplots(1, len(runs), figsize=(5.2 * len(runs), 4.2), squeeze=False)
    colors = colormaps["viridis"](np.linspace(0.0, 0.85, len(result["steps"])))
    for ax, run in zip(axes[0], runs):
        t = np.asarray(run["t_over_T"])
        for step, series, color in zip(run["steps"], run["derivatives"], colors):
            ax.semilogy(t, np.abs(series), color=color, lw=1.2, label=f"step {step:g} {run['wrt']}")
        for key, style in (("useful_horizon_T", "--"), ("converged_horizon_T", ":")):
            if run[key] is not None:
                ax.axvline(run[key], color="k", ls=style, lw=0.8, label=key.replace("_T", "").replace("_", " "))
        growth = run["growth_per_period"]
        grows = "" if growth is None else f": grows {growth:+.2f} e-folds / T"
        ax.set_title(f"{run['scene']}, {run['label']}{grows}", fontsize=9)
        ax.set_xlabel("horizon t / T")
        ax.set_ylabel(f"|dJ/d{run['wrt']}| (J: displacement along the wave, R)")
        ax.legend(fontsize=7)
    fig.suptitle(f"walker gradients against the horizon, {result['device_name']}", fontsize=10)
    fig.tight_layout()
    write_png(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench gradient_horizon", description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--scenes", nargs="+", choices=SCENES, default=list(SCENES))
    parser.add_argument("--mechanics", nargs="+", choices=tuple(MECHANICS), default=list(MECHANICS))
    parser.add_argument("--periods", type=float, default=6.0)
    parser.add_argument("--wrt", choices=PER_WORLD, default="AC", help="the parameter θ (a per-world one)")
    parser.add_argument("--steps", nargs="+", type=float, default=list(STEPS),
                        help="relative steps of θ, largest first")  # fmt: skip
    parser.add_argument("--sensitive", choices=("true", "false"), default="true")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="fixed for every run")
    parser.add_argument("--quick", action="store_true", help="the scenes' quick meshes (a CPU smoke run)")
    parser.add_argument("--out", default=".")
    args = parser.parse_args(argv)
    device = resolve_device(args.device)
    runs = []
    for scene in args.scenes:
        for mechanics in args.mechanics:
            run = measure(scene, mechanics, args, device)
            print(f"{scene} {run['label']}: dJ/d{args.wrt} at the end {run['gradient_end']:+.4g}, useful horizon "
                  f"{run['useful_horizon_T']} T, converged {run['converged_horizon_T']} T, growth "
                  f"{run['growth_per_period']} e-folds a period")  # fmt: skip
            runs.append(run)
    result = {"benchmark": "gradient_horizon", "date": date.today().isoformat(), **describe_device(device),
              "quick": args.quick, "periods": args.periods, "steps": args.steps, "runs": runs}  # fmt: skip
    write_result(result, args.out, "gradient_horizon", chart)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
