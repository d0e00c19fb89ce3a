"""Accuracy against cost: the known answers (docs/theory/scenes.md#checks) over the settings a scene chooses.

    wavewarp bench accuracy --device cpu --out benchmarks/results [--quick] [--cases ...]

Five cases, each a sweep of settings; every point is (wall seconds of one computation, its error
against the exact answer):

* `spectrum`: the largest relative error of the 48 sphere eigenvalues l(l+1)/R², l = 1..6, of the
  operator a telegraph stepper applies (M⁻¹K with the lumped mass, W_2 K with two mass corrections;
  Loop subdivision or P1) over level, quadrature rule and dtype: a host float64 eigensolve of the K
  and M that dtype built. Cost: one pole-to-pole crossing (t = πR/γ) of the telegraph leapfrog with
  that operator at 0.9 × its bound (operator build, stability guard, steps).
* `telegraph`: c(t) against the Legendre series of c_tt + α c_t = γ² Δc on a sphere (docs/theory/scenes.md) over
  level, dt (fractions of the stability bound), dtype, discretisation and mass corrections.
  "modes": c0 = Σ P_l(cos θ), l = 1..6, with an initial velocity (unit sphere, γ = 1, α = 0.1,
  t = π); "pulse": the starfish's and buckling's outgoing Gaussian (R = 10, width √2, γ = 1,
  α = 0.001) at t = πR/2γ, its front on the equator; "wide pulse": the ascidian's (width R/2).
  Error: max over the nodes of |c − c_exact| over max |c_exact| (modes) or the pulse's peak C0 = 1.
  Cost: build, initial data, guard and steps.
* `radius`: a sphere under uniform c = 1 relaxed by `Shell.relax` against the minimiser λ of the
  closed-form energy E(r = λR) (docs/theory/scenes.md), for each scene family's AC, AI, h/R, μV and model, over
  level, quadrature rule, dtype and relaxation tolerance (× the dtype's default). Error:
  |r̄/R − λ| / |1 − λ|, r̄ the mean radius of the limit points. Cost: Shell build and relax.
* `arrival`: an outgoing Gaussian's front reaches geodesic distance s at s/γ + t0. "sphere": the
  starfish's pulse, great circles, θ in [π/4, 3π/4] (not the ascidian's: s/γ holds for a narrow
  pulse only, its half-peak arrival runs 13–15% off it at every level; "wide pulse" bounds that
  wave); "cube": the wave guides' pulse (L = 20, width √2) from a face centre, distances in the net
  unfolded about the top face's edges. Over level / divisions, rule, dt, dtype, discretisation and
  mass corrections. Arrival is the scenes' (`wavewarp.scene.ArrivalTimes`: half the first peak,
  field values sampled every 0.1 width/γ); error |v/γ − 1| for the speed v fitted to it. Cost: build, guard and steps (not the sampling).
* `front`: the FitzHugh–Nagumo front on the sphere walker's rest sphere (R = 25, its kinetics, dt and
  Gaussian start) against the continuum front speed of a 1-D lattice solve converged in h and dt
  (docs/theory/scenes.md; the bistable speed √(2γ²)(½ − ν) of w ≡ 0 beside it), over level, dtype and mass
  corrections. Coarse lattices pin the front (propagation failure): a front that does not cross the
  probes' window counts as speed 0, error 1. Error |v − v_ref| / v_ref for v fitted to the arrival
  times of c = 0.5 at geodesic distances θ ∈ [π/4, 3π/4] from the origin. Cost: build, guard, steps.

Every timed computation follows an untimed one of the same kind on the same mesh (kernels loaded,
per-mesh patch tables cached, as in a scene after its first frame). Per configuration the points
that no other point beats in both time and error form the Pareto front (marked in the charts).
For each scene (scenes/*.py) and each case that bounds its accuracy (NEEDS; the tolerances and why
in TOLERANCES) the recommended setting is the cheapest point below the tolerance among the settings
the scene can select, float32 when a float32 point meets it; it is set beside the point of the
scene's current defaults. Writes accuracy_<device>.json and accuracy_<case>_<device>.png.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import sys
import time
from datetime import date

import warp as wp

from wavewarp.device import describe_device, device_tag, resolve_device
from wavewarp.io import write_json, write_png
from wavewarp.mesh import cube, prism
from wavewarp.quadrature import triangle_rule
from wavewarp.parameters import load_scene, resolve
from wavewarp.runs import mean_edge

from wavewarp.benchmarks.accuracy_cases import (  # noqa: E402
    CASES,
    LABELS,
    NEEDS,
    PROXIES,
    SCENE_DT,
    TOLERANCES,
    front_references,
    sphere,
    sweeps,
)


def pareto_front(points) -> list:
    """Indices of the points no other point beats in both seconds and error (≤ in both, < in one)."""
    order = sorted(range(len(points)), key=lambda i: (points[i]["seconds"], points[i]["error"]))
    front, best, best_seconds = [], math.inf, None
    for i in order:
        seconds, error = points[i]["seconds"], points[i]["error"]
        if error < best or (error == best and seconds == best_seconds):
            front.append(i)
            best, best_seconds = error, seconds
    return sorted(front)


def usable(point) -> bool:
    return point.get("converged", True) and math.isfinite(point["error"])


def mark_front(points) -> None:
    candidates = [i for i, point in enumerate(points) if usable(point)]
    front = {candidates[i] for i in pareto_front([points[i] for i in candidates])}
    for i, point in enumerate(points):
        point["pareto"] = i in front


# ---------------------------------------------------------------- recommendations per scene


@functools.lru_cache(maxsize=None)
def icosphere_edge(level) -> float:
    return mean_edge(sphere(1.0, level))


def equivalent_level(mesh, radius) -> int:
    """The finest icosphere level whose mean control edge, in units of its radius, is no shorter than
    the mesh's in units of `radius`: the lumped operator's error on the modes λR² ≤ 42 (l ≤ 6 on the
    sphere) goes with that edge, not with the vertex count, and so do the FHN front's pinning and
    speed, set by γ²/h² (BENCHMARKS.md#accuracy-against-cost)."""
    edge, level = mean_edge(mesh) / radius, 0
    while icosphere_edge(level + 1) >= edge:
        level += 1
    return level


def box_geometry(scene) -> tuple:
    """A box scene's mesh maker, edge L and length unit R: the walkers' own (L_OVER_R in the
    scene), L/2 for the wave guides (their radius proxy's inscribed sphere, BOX_SPHERE)."""
    module = load_scene(scene)
    edge = resolve(module.Parameters).edge
    return (prism if "prism" in scene else cube), edge, edge / getattr(module, "L_OVER_R", 2.0)


def box_level(scene, divisions) -> int:
    make, edge, radius = box_geometry(scene)
    return equivalent_level(make(edge, divisions), radius)


def box_divisions(scene, level) -> int:
    """The fewest (even) divisions at which the scene's box resolves `level` (equivalent_level)."""
    divisions = 2
    while box_level(scene, divisions) < level:
        divisions += 2
    return divisions


def scene_setting(scene) -> dict:
    """The scene's current defaults on the benchmark's axes, and what it can select."""
    p = vars(resolve(load_scene(scene).Parameters))
    walker = "periods" in p
    setting = {"dtype": p["dtype"], "rule": p.get("rule", "3"), "discretization": "subdivision"}
    if "level" in p:
        setting["level"] = p["level"]
    else:  # a box: its (even) divisions, and the icosphere level it resolves as well, for the sphere proxies
        divisions = p["divisions"] + p["divisions"] % 2
        setting.update(divisions=divisions, level=box_level(scene, divisions))
    if walker:  # explicit FHN (wavewarp/walker.py); the dynamics never relaxes: the default tolerance's radius
        setting.update(mass_corrections=p["mass_corrections"], fhn_scheme=p["fhn_scheme"], tol_factor=1.0)
    else:
        setting.update(mass_corrections=p["mass_corrections"], dt_fraction=SCENE_DT if p["dt"] == 0 else None,
                       tol_factor=1.0 if p["relax_tol"] == 0 else None)  # fmt: skip
    # The relax tolerance stays the dtype's default: the uniform-c radius does not see a quasi-static path's
    # sensitivity to it (ascidian, level 4, p = 2, t = 10: × 10 ends 0.46 R off float64, × 1 within 2e-3 R).
    fixed = {"discretization", "tol_factor"} | ({"rule"} if "rule" not in p else set())
    return {"setting": setting, "fixed": sorted(fixed)}


AXES = ("level", "divisions", "rule", "discretization", "mass_corrections", "fhn_scheme", "dt_fraction", "dtype",
        "tol_factor")


def axes_of(point) -> dict:
    return {axis: point[axis] for axis in AXES if axis in point}


def matches(point, setting, names) -> bool:
    """Whether the point agrees with the setting on the named axes both have."""
    return all(point[name] == setting[name] for name in names if name in point and name in setting)


def cheapest(points, tolerance):
    """The cheapest point below the tolerance, float32 when a float32 point meets it."""
    meeting = [p for p in points if usable(p) and p["error"] <= tolerance]
    single = [p for p in meeting if p["dtype"] == "float32"]
    return min(single or meeting, key=lambda p: p["seconds"]) if meeting else None


def recommend(results) -> list:
    """Per scene and need (NEEDS): the recommended point, the scene's current one, and the cheapest
    point of any setting (`unrestricted`) where the scene could not select it."""
    out = []
    for scene, needs in NEEDS.items():
        current = scene_setting(scene)
        setting = current["setting"]
        for case, configuration in needs:
            points = results.get(case, {}).get(configuration, {}).get("points")
            if not points:
                continue
            tolerance, why = TOLERANCES[case]
            size_axis = "divisions" if configuration == "cube" else "level"
            selectable = [p for p in points if matches(p, setting, current["fixed"])]
            best, any_setting = cheapest(selectable, tolerance), cheapest(points, tolerance)
            now = [p for p in points if matches(p, setting, [size_axis, *AXES[2:]])]
            entry = {"scene": scene, "case": case, "configuration": configuration, "tolerance": tolerance,
                     "fixed": {name: setting[name] for name in current["fixed"]},
                     "setting": axes_of(best) if best else None, "error": best["error"] if best else None,
                     "seconds": best["seconds"] if best else None,
                     "why": (f"cheapest {best['dtype']} point of the sweep with error {best['error']:.2g} <= {tolerance:g} "
                             f"among the settings the scene can select (fixed: {', '.join(current['fixed'])}); " if best
                             else f"no point of the sweep the scene can select meets {tolerance:g}; ") + why,
                     "proxy": PROXIES.get((scene, configuration)),
                     "current": {"setting": {k: setting.get(k) for k in AXES if k in setting},
                                 "error": now[0]["error"] if now else None, "seconds": now[0]["seconds"] if now else None,
                                 "meets": (now[0]["error"] <= tolerance) if now else None}}  # fmt: skip
            if any_setting is not None and any_setting is not best:
                entry["unrestricted"] = {"setting": axes_of(any_setting), "error": any_setting["error"],
                                         "seconds": any_setting["seconds"]}  # fmt: skip
            out.append(entry)
    return out


def combined(recommendations) -> dict:
    """Per scene, one setting meeting every need: the largest level / divisions and mass corrections,
    the smallest dt and tolerance factors, the rule with the most points, float64 if any need asks for it.
    Box scenes get `divisions` in place of their proxies' icosphere level: the most of their needs'
    divisions and of the fewest that resolve that level (box_divisions)."""
    out = {}
    for r in recommendations:
        scene = out.setdefault(r["scene"], {})
        if r["setting"] is None:
            scene.setdefault("unmet", []).append(r["case"])
            continue
        for axis, value in r["setting"].items():
            if axis == "discretization":
                scene[axis] = value
            elif axis in ("level", "divisions", "mass_corrections"):
                scene[axis] = max(scene.get(axis, value), value)
            elif axis in ("dt_fraction", "tol_factor"):
                scene[axis] = min(scene.get(axis, value), value)
            elif axis == "dtype":
                scene[axis] = "float64" if "float64" in (scene.get(axis), value) else "float32"
            elif axis == "fhn_scheme":
                scene[axis] = "heun" if "heun" in (scene.get(axis), value) else "explicit"
            elif axis == "rule":
                scene[axis] = max(scene.get(axis, value), value, key=lambda rule: len(triangle_rule(rule)[1]))
    for name, scene in out.items():
        if "level" in scene and "divisions" in scene_setting(name)["setting"]:
            scene["divisions"] = max(scene.get("divisions", 2), box_divisions(name, scene.pop("level")))
    return out


# ---------------------------------------------------------------- charts


def colour_key(case, point) -> str:
    if case == "radius":
        return f"rule {point['rule']}"
    label = LABELS[point["discretization"], point["mass_corrections"]]
    if point.get("fhn_scheme", "explicit") != "explicit":
        label += f", {point['fhn_scheme']}"
    return f"{label}, rule {point['rule']}" if case == "arrival" and point["rule"] not in ("3", "-") else label


def marker_key(case, point) -> str:
    if case in ("spectrum", "front"):
        return f"L{point['level']}"
    if case == "radius":
        return f"L{point['level']}, tol × {point['tol_factor']:g}"
    return f"dt {point['dt_fraction']:g} × bound"


def chart(case, result, recommendations, path, title) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import NullFormatter

    configurations = result["configurations"]
    columns = min(len(configurations), 4)
    rows = -(-len(configurations) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(max(5.2 * columns, 10.5), 4.6 * rows), squeeze=False)
    colours, markers = {}, {}
    palette, shapes = plt.get_cmap("tab10"), "os^Dv<>pPX*h"
    for ax, (name, block) in zip(axes.flat, configurations.items()):
        points = [p for p in block["points"] if usable(p) and p["error"] > 0]
        for p in points:
            colour = colours.setdefault(colour_key(case, p), palette(len(colours) % 10))
            marker = markers.setdefault(marker_key(case, p), shapes[len(markers) % len(shapes)])
            ax.scatter(p["seconds"], p["error"], marker=marker, s=30, edgecolors=[colour], linewidths=1.1,
                       facecolors=[colour] if p["dtype"] == "float32" else "none")  # fmt: skip
        front = sorted((p for p in points if p["pareto"]), key=lambda p: p["seconds"])
        if front:
            ax.step([p["seconds"] for p in front], [p["error"] for p in front], where="post", color="k", lw=1.0)
            ax.scatter([p["seconds"] for p in front], [p["error"] for p in front], s=110, facecolors="none",
                       edgecolors="k", linewidths=0.8)  # fmt: skip
            for p in front:
                size = f"L{p['level']}" if "level" in p else f"n{p['divisions']}"
                ax.annotate(size, (p["seconds"], p["error"]), textcoords="offset points", xytext=(5, 4), fontsize=7)
        for r in recommendations:
            if r["case"] == case and r["configuration"] == name:
                ax.axhline(r["tolerance"], color="0.5", ls="--", lw=0.8)
                if r["setting"] is not None:
                    ax.scatter(r["seconds"], r["error"], marker="*", s=220, color="gold", edgecolors="k", zorder=5)
                if r["current"]["error"]:
                    ax.scatter(r["current"]["seconds"], r["current"]["error"], marker="x", s=90, color="red", zorder=6)
        scenes = sorted({r["scene"] for r in recommendations if r["case"] == case and r["configuration"] == name})
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(f"{name}" + (f"\n(scenes: {', '.join(scenes)})" if scenes else ""), fontsize=9)
        ax.set_xlabel(result["cost"], fontsize=8)
        ax.set_ylabel(result["error_label"], fontsize=8)
        ax.grid(True, which="major", alpha=0.3)
    for ax in list(axes.flat)[len(configurations):]:
        ax.axis("off")
    handles = [Line2D([], [], color=c, marker="o", ls="", label=k) for k, c in colours.items()]
    handles += [Line2D([], [], color="0.3", marker=m, ls="", markerfacecolor="none", label=k) for k, m in markers.items()]
    handles += [Line2D([], [], color="0.3", marker="o", ls="", label="filled: float32, open: float64"),
                Line2D([], [], color="k", lw=1.0, marker="o", markerfacecolor="none", markersize=10, label="Pareto front"),
                Line2D([], [], color="0.5", ls="--", label="scene tolerance"),
                Line2D([], [], color="gold", marker="*", markeredgecolor="k", ls="", markersize=12,
                       label="recommended (cheapest meeting it)"),
                Line2D([], [], color="red", marker="x", ls="", markersize=8, label="scene's current defaults")]  # fmt: skip
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=7, frameon=False)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout(rect=(0, 0.04 + 0.035 * math.ceil(len(handles) / 4) / rows, 1, 1))
    write_png(fig, path, dpi=110)


DESCRIPTIONS = {
    "spectrum": ("max relative error of the eigenvalues l(l+1)/R², l = 1..6",
                 "seconds: one crossing t = πR/γ (build, guard, steps at 0.9 × bound)"),
    "telegraph": ("max |c − c_exact| / scale (Legendre series)", "seconds: build, initial data, guard, steps"),
    "radius": ("|r̄/R − λ| / |1 − λ| (closed-form E(λ))", "seconds: Shell build + relax"),
    "arrival": ("|v/γ − 1|, v fitted to the arrival times", "seconds: build, guard, steps"),
    "front": ("|v − v_ref| / v_ref (1: the front stalls)", "seconds: build, guard, steps (the walker's dt = 0.5)"),
}  # fmt: skip


# ---------------------------------------------------------------- main


def save_json(path, result) -> None:
    write_json(path, result)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench accuracy", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    parser.add_argument("--out", default="benchmarks/results", help="folder for the JSON and the charts")
    parser.add_argument("--quick", action="store_true", help="coarse levels and fewer settings (a smoke test, ~30 s on a CPU)")
    parser.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES), help="cases to run (default: all)")
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    os.makedirs(args.out, exist_ok=True)
    tag = device_tag(device)
    json_path = os.path.join(args.out, f"accuracy_{tag}.json")
    began = time.perf_counter()
    result = {"benchmark": "accuracy", "date": date.today().isoformat(), **describe_device(device), "quick": args.quick, "tolerances": {case: {"tolerance": t, "why": why} for case, (t, why) in TOLERANCES.items()},
              "cases": {}}  # fmt: skip
    plan = sweeps(args.quick)
    for case in args.cases:
        error_label, cost = DESCRIPTIONS[case]
        block = {"error_label": error_label, "cost": cost, "configurations": {}}
        if case == "front":
            block["reference"] = front_references()
            print(f"front reference: {json.dumps(block['reference'])}", flush=True)
        result["cases"][case] = block
        case_began = time.perf_counter()
        for configuration, jobs in plan[case].items():
            points = []
            for point_function, arguments in jobs:
                points.append(point_function(device.alias, *arguments))
                print(f"{case:9s} {configuration:14s} {json.dumps(axes_of(points[-1]))}: error {points[-1]['error']:.3e}"
                      f"  {points[-1]['seconds']:.3f} s", flush=True)  # fmt: skip
            mark_front(points)
            block["configurations"][configuration] = {"points": points}
            block["wall_time_s"] = time.perf_counter() - case_began  # the sweep's own, eigensolves and sampling included
            save_json(json_path, {**result, "partial": True})
    cases = {case: result["cases"][case]["configurations"] for case in result["cases"]}
    result["recommendations"] = recommend(cases)
    result["scene_settings"] = combined(result["recommendations"])
    result["wall_time_s"] = time.perf_counter() - began
    save_json(json_path, result)
    for case in result["cases"]:
        chart(case, result["cases"][case], result["recommendations"], os.path.join(args.out, f"accuracy_{case}_{tag}.png"),
              f"wavewarp accuracy against cost: {case}, {device.name} ({result['date']})")  # fmt: skip
    for r in result["recommendations"]:
        now = r["current"]
        print(f"{r['scene']:15s} {r['case']:9s} {r['configuration']:14s} tol {r['tolerance']:g}: "
              f"recommended {json.dumps(r['setting'])} ({r['error'] if r['error'] is None else format(r['error'], '.2e')}); "
              f"current {now['error'] if now['error'] is None else format(now['error'], '.2e')}"
              f" ({'meets' if now['meets'] else 'fails' if now['meets'] is not None else 'not in the sweep'})", flush=True)  # fmt: skip
    print(f"wrote {json_path} and accuracy_<case>_{tag}.png ({result['wall_time_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
