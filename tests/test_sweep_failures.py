"""Sweeps that tell the truth (docs/theory/sweeps.md; issue 57, "Restarts and outputs" 5): a failed point makes
the sweep exit non-zero with one line saying why, and a re-run tries it again; --device is checked as `run`
checks it; two sweeps into one folder compute each point once; a Dask worker killed mid-batch costs only that
batch."""

import concurrent.futures
import json
import os
import subprocess
import sys
import textwrap
import time

import pytest
import warp as wp

from wavewarp import cli
from wavewarp.sweep import SweepSpec, sweep

HANG_GUARD_S = 600  # waiting on other processes fails after this (a guard against hanging, no limit)


def scene_script(folder, body: str) -> str:
    """A scene script: cube-waves whose `build` first runs `body` (with `p`, `log` = FOLDER/builds.log)."""
    path = folder / "scene.py"
    header = textwrap.dedent(f"""
        import os, signal
        from wavewarp.scenes import cube_waves
        from wavewarp.scenes.cube_waves import NAME, QUICK, Parameters

        def build(p, **options):
            log = {str(folder / "builds.log")!r}
        """)
    path.write_text(header + textwrap.indent(textwrap.dedent(body).strip() + "\n", "    ")
                    + "    return cube_waves.build(p, **options)\n")
    return str(path)


def builds(folder) -> list:
    """The points the scene script was built for, one line each, in order."""
    return (folder / "builds.log").read_text().split()


def threaded_sweep(monkeypatch):
    """The command line's sweeps on a thread of this process instead of a Dask cluster."""
    def on_a_thread(spec, out, **options):
        with concurrent.futures.ThreadPoolExecutor(max_workers=1) as pool:
            return sweep(spec, out, executor=pool, batch=options["batch"], report=options["report"])

    monkeypatch.setattr(cli, "sweep", on_a_thread)


def test_a_failed_point_exits_nonzero_saying_why_and_a_rerun_tries_it_again(tmp_path, capsys, monkeypatch):
    """Case 5: a point whose build fails (here for want of a GPU, until one is there) makes the sweep exit 1 with
    one line naming the point and the error; --json counts it; the re-run computes it, and only it."""
    script = scene_script(tmp_path, f"""
        if p.gamma == 1.0 and not os.path.exists({str(tmp_path / "gpu")!r}):
            raise ValueError("device 'cuda' is not available")
        open(log, "a").write(f"gamma={{p.gamma}}\\n")
    """)
    threaded_sweep(monkeypatch)
    command = ["sweep", script, "--quick", "--grid", "gamma=0.8,1.0", "--device", "cpu", "--out", str(tmp_path / "s")]
    assert cli.main(command) == 1
    out, err = capsys.readouterr()
    assert "point gamma=1.0_seed=0 failed: device 'cuda' is not available" in err and "Traceback" not in err
    assert "computed 1, skipped 0, failed 1" in out
    (tmp_path / "gpu").touch()
    assert cli.main([*command, "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == {"computed": 1, "skipped": 1, "failed": 0, "failures": {}}
    assert builds(tmp_path) == ["gamma=0.8", "gamma=1.0"]


@pytest.mark.skipif(wp.is_cuda_available(), reason="needs a machine without CUDA")
def test_sweep_and_cluster_refuse_cuda_without_a_gpu(tmp_path, capsys):
    """Case 5: `--device cuda` without a GPU is refused as `run` refuses it, before any folder or cluster."""
    assert cli.main(["sweep", "cube-waves", "--grid", "gamma=1", "--device", "cuda", "--out", str(tmp_path / "s")]) == 2
    assert "device 'cuda' is not available" in capsys.readouterr().err and not (tmp_path / "s").exists()
    assert cli.main(["cluster", "--device", "cuda"]) == 2
    assert "device 'cuda' is not available" in capsys.readouterr().err


def test_two_sweeps_into_one_folder_compute_each_point_once(tmp_path):
    """Two sweeps of the same 4 points into one folder, started together: each point is computed by one of
    them (a lock per point), so the points they computed sum to 4 and every point has its result."""
    script = scene_script(tmp_path, 'open(log, "a").write(f"gamma={p.gamma}\\n")')
    program = textwrap.dedent(f"""
        import concurrent.futures, json, os, sys, time
        from wavewarp.sweep import SweepSpec, sweep
        from wavewarp.scenes import cube_waves  # imported and loaded before the start
        spec = SweepSpec({script!r}, grid={{"gamma": ["0.8", "0.9", "1.0", "1.1"]}}, quick=True, device="cpu")
        open(sys.argv[1], "w").close()
        while not os.path.exists({str(tmp_path / "go")!r}):
            time.sleep(0.01)
        with concurrent.futures.ThreadPoolExecutor(max_workers=1) as pool:
            rows = sweep(spec, {str(tmp_path / "s")!r}, executor=pool, report=lambda message: None)
        print(json.dumps(rows.summary()))
    """)
    sweeps = [subprocess.Popen([sys.executable, "-c", program, str(tmp_path / f"ready{k}")], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True) for k in range(2)]
    start = time.monotonic()
    while not all((tmp_path / f"ready{k}").exists() for k in range(2)):
        assert all(s.poll() is None for s in sweeps) and time.monotonic() - start < HANG_GUARD_S
        time.sleep(0.01)
    (tmp_path / "go").touch()
    summaries = []
    for process in sweeps:
        out, err = process.communicate(timeout=HANG_GUARD_S)
        assert process.returncode == 0, err
        summaries.append(json.loads(out))
    assert sum(s["computed"] for s in summaries) == 4 and all(s["failed"] == 0 for s in summaries)
    assert sorted(builds(tmp_path)) == ["gamma=0.8", "gamma=0.9", "gamma=1.0", "gamma=1.1"]
    assert sorted(name for name in os.listdir(tmp_path / "s" / "points") if not name.startswith(".")) == [
        f"gamma={g}_seed=0.json" for g in ("0.8", "0.9", "1.0", "1.1")]


@pytest.mark.slow
def test_a_dask_worker_killed_mid_batch_costs_only_that_batch(tmp_path):
    """A local Dask cluster of one worker runs two batches; the worker dies (SIGKILL, as the OOM killer would)
    the first time it builds gamma=1.0: Dask runs that batch again on the restarted worker, the other batch
    is not computed again, and the sweep ends with both points done."""
    script = scene_script(tmp_path, f"""
        open(log, "a").write(f"gamma={{p.gamma}}\\n")
        if p.gamma == 1.0 and not os.path.exists({str(tmp_path / "killed")!r}):
            open({str(tmp_path / "killed")!r}, "w").close()
            os.kill(os.getpid(), signal.SIGKILL)
    """)
    spec = SweepSpec(script, grid={"gamma": ["0.8", "1.0"]}, quick=True, device="cpu")
    rows = sweep(spec, str(tmp_path / "s"), workers=1, report=lambda message: None)
    assert (rows.computed, rows.failures) == (2, {}) and [row["status"] for row in rows] == ["done", "done"]
    assert sorted(builds(tmp_path)) == ["gamma=0.8", "gamma=1.0", "gamma=1.0"]
