"""Convergence of the quasi-static scenes' observables in the time step and the mesh, for each reading of the model:
transport conservative or material, times coupling quasi-static or overdamped (docs/theory/transport.md).

    wavewarp bench convergence --scenes ascidian starfish buckling --levels 4 5 6 --halvings 3 \
        --readings conservative/overdamped conservative/quasi-static --device cuda --workers 6 --out DIR

A point is one run of a scene at a reading, an icosphere level L and a time step dt = dt₄ / 2^k, dt₄ the scene's
automatic step at level 4 (an exact divisor of its frame interval), with a relaxation (or overdamped step) after
every wave step. A level takes the steps its wave's stability bound allows: k ≥ L − 4 (the bound halves with the
edge). Per scene and reading the tables hold, for each observable, the sequence over dt at each level and over the
levels at each dt, with the observed order and the Richardson estimate (benchmarks/convergence_tables.py).
Observables: the oocytes' `--json` measurements (front speed, its nonlinearity and arrival spread, the shape
asymmetry and its mode, c_min while the front expands and while it converges, C against the invariant, the smallest
area ratio, the contraction depth and profiles) and, for overdamped points, `equilibrium_lag`: how far the shell
lags the quasi-static equilibrium of its own concentrations at the profiles' frames, max |x − x_eq| over
max |x_eq − X| (X the rest shape), x_eq relaxed from x. The buckling scene: its symmetry numbers and amplitude.

Points are written to DIR/points/*.json as they finish (a re-run skips them); `--tables` only rebuilds
DIR/convergence.json, DIR/convergence.md and the charts from them. Workers are processes (several share one GPU).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import math
import multiprocessing
import os
import time
from datetime import date

from wavewarp.benchmarks.convergence_tables import default_errors, markdown_row, profile_convergence, richardson

READINGS = ("conservative/quasi-static", "conservative/overdamped", "material/quasi-static", "material/overdamped")
OOCYTE_OBSERVABLES = (
    "wave_speed",
    "speed_nonlinearity",
    "arrival_spread",
    "shape_asymmetry",
    "min_concentration_expanding",
    "min_concentration_converging",
    "total_concentration_error",
    "min_area_ratio",
    "contraction_depth",
    "equilibrium_lag",
)
BUCKLING_OBSERVABLES = ("n_onset", "n_mode", "n_max", "amplitude_max_h", "t_n_max")


def point_name(point: dict) -> str:
    transport, coupling = point["reading"].split("/")
    extra = "".join(f"_{s.replace('=', '')}" for s in point["sets"])
    return f"{point['scene']}_{transport}_{coupling}_L{point['level']}_k{point['k']}{extra}"


def base_step(scene: str, sets: list, device: str) -> float:
    """dt₄: the scene's automatic step at level 4 (its frame interval divided by whole steps)."""
    from wavewarp.parameters import load_scene, resolve

    module = load_scene(scene)
    p = resolve(module.Parameters, None, [*sets, "level=4", "coupling=quasi-static"])
    run = module.build(p, device=device, report=lambda message: None)
    return float(run.resolved["dt"])


def run_point(point: dict) -> dict:
    """One run; its measurements, per-frame series and (overdamped) its lag behind equilibrium."""
    import warp as wp

    from wavewarp.driver import simulate
    from wavewarp.parameters import load_scene, resolve

    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    module = load_scene(point["scene"])
    transport, coupling = point["reading"].split("/")
    sets = [
        *point["sets"],
        f"level={point['level']}",
        f"dt={point['dt']!r}",
        "relax_every=1",
        f"transport={transport}",
        f"coupling={coupling}",
    ]
    p = resolve(module.Parameters, None, sets)
    start = time.perf_counter()
    run = module.build(p, device=point["device"], report=lambda message: None)
    frames = _Frames(start + point.get("max_seconds", math.inf))
    outcome = simulate(run, [frames])
    result = {
        **point,
        "wall_time_s": time.perf_counter() - start,
        "stopped": outcome.failure,
        "interrupted": outcome.interrupted,
        "frames": outcome.frames,
        "steps": run.steps,
        "measurements": _plain(outcome.measurements),
        "series": _series(run),
    }
    if coupling == "overdamped" and point["scene"] != "buckling":
        result["measurements"]["equilibrium_lag"] = _lag(run, frames)
    return result


class _Frames:
    """A writer that keeps every frame's positions and concentrations in memory, and interrupts the run (as Ctrl-C
    does: the frames so far are measured) once the clock passes `deadline`."""

    def __init__(self, deadline: float = math.inf):
        self.times, self.x, self.c = [], [], []
        self.deadline = deadline

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def add_frame(self, time_: float, frame: dict) -> None:
        self.times.append(float(time_))
        self.x.append(frame["positions"].copy())
        self.c.append(frame["concentration"].copy())
        if time.perf_counter() > self.deadline:
            raise KeyboardInterrupt


def _lag(run, frames: _Frames) -> float | None:
    """The largest relative lag behind the quasi-static equilibrium over the frames nearest PROFILE_FRACTIONS (those
    whose profiles the run reports)."""
    import numpy as np

    from wavewarp.measurements import PROFILE_FRACTIONS
    from wavewarp.relax import RelaxationError

    if len(frames.times) < 2:
        return None
    shell, rest = run.shell, run.mesh.vertices
    shell.terms = ()  # the equilibrium of the frame's own concentrations, without the step's drag
    times = np.array(frames.times)
    lags = []
    for fraction in PROFILE_FRACTIONS:
        j = int(np.argmin(np.abs(times - fraction * times[-1])))
        x, c = frames.x[j].astype(np.float64), frames.c[j].astype(np.float64)
        try:
            equilibrium = shell.relax(x, c, max_iterations=20000, method="auto")
        except RelaxationError:
            return None
        lags.append(float(np.abs(x - equilibrium).max() / max(np.abs(equilibrium - rest).max(), 1e-300)))
    return max(lags)


def _series(run) -> dict:
    """Per frame: time and the scene's profile values that are numbers or vectors (asymmetry, mode, profile)."""
    series = {"time": [float(t) for t, _ in run.profiles]}
    if run.profiles and len(run.profiles[0][1]) >= 3:  # oocytes: (curvature radius, asymmetry, contraction)
        series["shape_asymmetry"] = [float(v[1][0]) for _, v in run.profiles]
        series["shape_asymmetry_mode"] = [int(v[1][1]) for _, v in run.profiles]
    balance = getattr(run, "balance", None)
    if balance is not None:
        series["min_concentration"] = [float(m[0]) for _, m in balance.frame_minima]
    return series


def _plain(value):
    """JSON-safe copies (NumPy scalars and arrays to Python numbers and lists)."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


def points(scenes, readings, levels, halvings: int, sets: list, device: str, steps: dict, max_seconds: float) -> list:
    out = []
    for scene in scenes:
        for reading in readings:
            for level in levels:
                for k in range(max(0, level - 4), halvings + 1):
                    out.append(
                        {
                            "scene": scene,
                            "reading": reading,
                            "level": level,
                            "k": k,
                            "dt": steps[scene] / 2**k,
                            "sets": list(sets),
                            "device": device,
                            "max_seconds": max_seconds,
                        }
                    )
    return out


# ---------------------------------------------------------------- tables


def tables(results: list) -> dict:
    """Per scene and reading: every observable's sequences over dt (per level) and over levels (per dt)."""
    groups = {}
    for r in results:
        groups.setdefault((r["scene"], r["reading"], " ".join(r["sets"])), []).append(r)
    out = {}
    for (scene, reading, sets), members in sorted(groups.items()):
        names = BUCKLING_OBSERVABLES if scene == "buckling" else OOCYTE_OBSERVABLES
        by = {(r["level"], r["k"]): r for r in members}
        entry = {"time_step": {}, "mesh": {}, "stopped": {point_name(r): r["stopped"] for r in members if r["stopped"]}}
        for level in sorted({lv for lv, _ in by}):
            ks = sorted(k for lv, k in by if lv == level)
            entry["time_step"][f"L{level}"] = _sequence([by[(level, k)] for k in ks], names, [f"k{k}" for k in ks])
        for k in sorted({k for _, k in by}):
            levels = sorted(lv for lv, kk in by if kk == k)
            if len(levels) >= 2:
                entry["mesh"][f"k{k}"] = _sequence([by[(lv, k)] for lv in levels], names, [f"L{lv}" for lv in levels])
        out[f"{scene} {reading} {sets}".strip()] = entry
    return out


def _sequence(runs: list, names, labels: list) -> dict:
    seq = {
        "members": labels,
        "dt": [r["dt"] for r in runs],
        "wall_time_s": [r["wall_time_s"] for r in runs],
        "stopped": [bool(r["stopped"] or r.get("interrupted")) for r in runs],
    }
    runs = [r if not (r["stopped"] or r.get("interrupted")) else {**r, "measurements": {}} for r in runs]
    for name in names:
        seq[name] = richardson([r["measurements"].get(name) for r in runs])
    modes = [r["measurements"].get("shape_asymmetry_mode") for r in runs]
    if any(m is not None for m in modes):
        seq["shape_asymmetry_mode"] = modes
    profiles = [r["measurements"].get("contraction_profiles") for r in runs]
    if all(profiles) and profiles:
        keys = sorted(set.intersection(*(set(p) for p in profiles)), key=float)
        seq["contraction_profiles"] = {key: profile_convergence([p[key] for p in profiles]) for key in keys}
    return seq


def defaults(results: list) -> dict:
    """Per oocyte scene whose default reading has points: its default's headline observables against the converged
    estimates (convergence_tables.default_errors)."""
    from wavewarp.parameters import load_scene

    out = {}
    for scene in sorted({r["scene"] for r in results} - {"buckling"}):
        p = load_scene(scene).Parameters()
        reading, sets = f"{p.transport}/{p.coupling}", [f"tau_m={p.tau_m:g}"] if p.coupling == "overdamped" else []
        members = {
            (r["level"], r["k"]): r["measurements"]
            for r in results
            if r["scene"] == scene
            and r["reading"] == reading
            and r["sets"] == sets
            and not (r["stopped"] or r.get("interrupted"))
        }
        if members:
            out[scene] = {
                "reading": reading,
                "sets": sets,
                "level": p.level,
                "observables": default_errors(members, p.level),
            }
    return out


def markdown(table: dict, header: str, checked: dict) -> str:
    lines = [header, ""]
    for scene, entry in checked.items():
        lines += [
            f"## {scene}'s default ({entry['reading']} {' '.join(entry['sets'])}, level {entry['level']}, its dt) "
            "against the converged values",
            "",
            "| observable | default | converged ± error (levels, step) | tolerance | within |",
            "|---|---|---|---|---|",
        ]
        for name, e in entry["observables"].items():
            where = f"L{e['levels'][0]}–L{e['levels'][-1]}, k{e['k_ref']}"
            tolerance = f"{e['tolerance']:g}" + (" rel." if e["kind"] == "relative" else "")
            lines.append(
                f"| {name} | {e['default']:.4g} | {e['estimate']:.4g} ± {e['error']:.2g} ({where}) | "
                f"{tolerance} | {e['meets']} |"
            )
        lines.append("")
    for group, entry in table.items():
        for kind, sequences in (("time step", entry["time_step"]), ("mesh", entry["mesh"])):
            for label, seq in sequences.items():
                lines += [
                    f"### {group}: {kind}, {label} ({' → '.join(seq['members'])})",
                    "",
                    "| observable | coarse → fine | order | estimate ± error |",
                    "|---|---|---|---|",
                ]
                for name, value in seq.items():
                    if isinstance(value, dict) and "values" in value:
                        lines.append(markdown_row(name, value))
                if "shape_asymmetry_mode" in seq:
                    lines.append(f"| shape_asymmetry_mode | {' → '.join(map(str, seq['shape_asymmetry_mode']))} | | |")
                for key, conv in seq.get("contraction_profiles", {}).items():
                    diffs = " → ".join(f"{d:.3g}" for d in conv["differences"])
                    order = "—" if conv["order"] is None else f"{conv['order']:.2f}"
                    error = "—" if conv["error"] is None else f"{conv['error']:.2g}"
                    lines.append(f"| profile at t = {key} (max diff) | {diffs} | {order} | ± {error} |")
                lines.append("")
        for name, why in entry["stopped"].items():
            lines.append(f"- {name} stopped: {why}")
        lines.append("")
    return "\n".join(lines)


def chart(table: dict, path: str) -> None:
    """Per group, the last difference's size against dt for the main observables (log-log)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wavewarp.io import write_png

    names = ("wave_speed", "shape_asymmetry", "min_concentration_expanding", "min_area_ratio", "contraction_depth")
    groups = list(table)
    fig, axes = plt.subplots(1, max(1, len(groups)), figsize=(4.2 * max(1, len(groups)), 3.6), squeeze=False)
    for ax, group in zip(axes[0], groups):
        for label, seq in table[group]["time_step"].items():
            for name in names:
                result = seq.get(name)
                if not isinstance(result, dict) or not result.get("differences"):
                    continue
                dts = seq["dt"][1 : len(result["differences"]) + 1]
                diffs = [abs(d) if d else float("nan") for d in result["differences"]]
                ax.loglog(dts, diffs, "o-", label=f"{name} ({label})")
        ax.set_title(group, fontsize=8)
        ax.set_xlabel("dt")
        ax.set_ylabel("|q(dt) − q(2 dt)|")
        ax.legend(fontsize=5)
    fig.tight_layout()
    write_png(fig, path)


def main(argv=None) -> int:
    import warp as wp

    from wavewarp.device import resolve_device
    from wavewarp.io import write_json

    parser = argparse.ArgumentParser(prog="wavewarp bench convergence", description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["ascidian", "starfish"])
    parser.add_argument("--readings", nargs="+", default=list(READINGS), choices=READINGS)
    parser.add_argument("--levels", nargs="+", type=int, default=[4])
    parser.add_argument("--halvings", type=int, default=3, help="time steps dt₄ / 2^k for k up to this")
    parser.add_argument(
        "--set",
        dest="sets",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a scene parameter for every point (e.g. tau_m=1, t_end=3, dtype=float64)",
    )
    parser.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    parser.add_argument("--workers", type=int, default=1, help="processes running points at once")
    parser.add_argument("--out", default="convergence", help="folder of points/ and the tables")
    parser.add_argument("--tables", action="store_true", help="only rebuild the tables from DIR/points")
    parser.add_argument(
        "--longest-first",
        action="store_true",
        help="start the finest points first (default: the shortest, so that a bench cut short keeps most)",
    )
    parser.add_argument(
        "--max-seconds",
        type=float,
        default=math.inf,
        help="interrupt a point's run after this long (it is kept, marked, and left out of the tables)",
    )
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    folder = os.path.join(args.out, "points")
    os.makedirs(folder, exist_ok=True)
    if not args.tables:
        steps = {scene: base_step(scene, args.sets, str(device)) for scene in args.scenes}
        todo = [
            p
            for p in points(
                args.scenes, args.readings, args.levels, args.halvings, args.sets, str(device), steps, args.max_seconds
            )
            if not os.path.exists(os.path.join(folder, point_name(p) + ".json"))
        ]
        todo.sort(key=lambda p: 4 ** p["level"] * 2 ** p["k"], reverse=args.longest_first)
        print(f"{len(todo)} points to run on {device} with {args.workers} workers", flush=True)
        context = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(args.workers, mp_context=context) as pool:
            futures = {pool.submit(run_point, p): p for p in todo}
            for future in concurrent.futures.as_completed(futures):
                point = futures[future]
                try:
                    result = future.result()
                except Exception as error:  # a crashed point is kept as such, the others go on
                    result = {
                        **point,
                        "wall_time_s": math.nan,
                        "stopped": f"{type(error).__name__}: {error}",
                        "frames": 0,
                        "steps": 0,
                        "measurements": {},
                        "series": {},
                    }
                write_json(os.path.join(folder, point_name(point) + ".json"), result)
                m = result["measurements"]
                print(
                    f"{point_name(point)}: {result['wall_time_s']:.0f} s, asym {m.get('shape_asymmetry')}, "
                    f"stopped {str(result['stopped'])[:80]}",
                    flush=True,
                )
    results = [
        json.load(open(os.path.join(folder, name))) for name in sorted(os.listdir(folder)) if name.endswith(".json")
    ]
    table = tables(results)
    devices = sorted({r["device"] for r in results})
    header = f"# Convergence tables (points run on {', '.join(devices)}; tables of {date.today().isoformat()})"
    checked = defaults(results)
    write_json(
        os.path.join(args.out, "convergence.json"),
        {
            "benchmark": "convergence",
            "devices": devices,
            "date": date.today().isoformat(),
            "defaults": checked,
            "tables": table,
        },
    )
    with open(os.path.join(args.out, "convergence.md"), "w") as f:
        f.write(markdown(table, header, checked))
    chart(table, os.path.join(args.out, "convergence.png"))
    print(f"wrote {args.out}/convergence.json, convergence.md, convergence.png ({len(results)} points)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
