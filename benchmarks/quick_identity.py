"""Every scene's quick run, bit for bit: a guard for refactors that must not change behaviour.

    wavewarp bench quick_identity --out DIR [--compare REF] [--scenes NAME ...]

Runs `wavewarp run SCENE --quick --device cpu --h5 DIR/SCENE.h5` for every scene (the CPU's
atomic sums run in a fixed order, so a run is reproducible bit for bit). With `--compare REF`, a
folder the same command filled with an earlier version, it compares every dataset of every
trajectory (`/mesh/*`, `/frames/*`) bitwise and writes DIR/quick_identity.json: per scene, the
datasets that differ and their largest difference. Exits 1 when any differs.
"""

from __future__ import annotations

import argparse
import json
import os
import time


def run_scene(scene: str, path: str) -> float:
    """One quick CPU run of `scene` into the HDF5 file `path`; returns its wall time."""
    import contextlib
    import io

    from wavewarp.cli import main as cli

    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        code = cli(["run", scene, "--quick", "--device", "cpu", "--overwrite", "--h5", path, "--out",
                    os.path.splitext(path)[0] + ".usda"])
    if code != 0:
        raise RuntimeError(f"wavewarp run {scene} --quick exited {code}")
    return time.perf_counter() - start


def compare(path: str, reference: str) -> dict:
    """Datasets of two trajectories that differ: {name: largest |difference|} (or a reason)."""
    import h5py
    import numpy as np

    differences = {}
    with h5py.File(path, "r") as a, h5py.File(reference, "r") as b:
        names = []
        a.visit(lambda name: names.append(name) if isinstance(a[name], h5py.Dataset) else None)
        expected = []
        b.visit(lambda name: expected.append(name) if isinstance(b[name], h5py.Dataset) else None)
        for name in sorted(set(names) | set(expected)):
            if name not in a or name not in b:
                differences[name] = "only in " + ("the reference" if name not in a else "this run")
                continue
            x, y = a[name][...], b[name][...]
            if x.shape != y.shape:
                differences[name] = f"shape {x.shape} against {y.shape}"
            elif not np.array_equal(x, y):
                differences[name] = float(np.max(np.abs(x.astype(np.float64) - y.astype(np.float64))))
    return differences


def main(argv=None) -> int:
    from wavewarp.io import write_json
    from wavewarp.parameters import scene_descriptions

    parser = argparse.ArgumentParser(prog="wavewarp bench quick_identity", description=__doc__.split("\n")[0])
    parser.add_argument("--out", required=True, help="folder for SCENE.h5 (and quick_identity.json)")
    parser.add_argument("--compare", default=None, help="folder of reference trajectories from an earlier version")
    parser.add_argument("--scenes", nargs="+", default=None, help="scenes to run (default: all)")
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    scenes = args.scenes or list(scene_descriptions())
    report, failed = {}, False
    for scene in scenes:
        path = os.path.join(args.out, f"{scene}.h5")
        wall = run_scene(scene, path)
        entry = {"wall_time_s": wall}
        if args.compare:
            entry["differences"] = compare(path, os.path.join(args.compare, f"{scene}.h5"))
            failed |= bool(entry["differences"])
        report[scene] = entry
        state = "" if not args.compare else ("identical" if not entry["differences"] else f"DIFFERS {entry['differences']}")
        print(f"{scene:16s} {wall:6.1f} s  {state}", flush=True)
    if args.compare:
        write_json(os.path.join(args.out, "quick_identity.json"), {"reference": os.path.abspath(args.compare), "scenes": report})
    print(json.dumps({"identical": not failed}) if args.compare else f"wrote {len(scenes)} trajectories to {args.out}")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
