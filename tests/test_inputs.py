"""Every input checked before anything runs (docs/theory/scenes.md "Sizes"; issue 57, "Restarts and outputs" 7
and 8): scene scripts that are no Python or do not load, a port out of range, baked USD levels, frame counts
and time steps whose cost is absurd, and a memory guard that respects the address-space (ulimit -v) and cgroup
limits, each a one-line error with the estimate where there is one."""

import os
import resource
import subprocess
import sys

import pytest
from trajectories import assert_refused, run_cli

from wavewarp import cli, sizing

QUICK = ["--quick", "--device", "cpu"]


@pytest.mark.parametrize("name, text, message", [
    ("mesh.obj", "v 0 0 0\n", "is not a Python file (.py)"),
    ("broken.py", "def build(p:\n", "is not valid Python: '(' was never closed (line 1)"),
    ("binary.py", "\0\1\2", "is not a Python text file"),
    ("failing.py", "import no_such_module_here\n", "failed to load: ModuleNotFoundError: No module named"),
])
def test_a_scene_script_that_does_not_load_is_one_line(name, text, message, tmp_path, capsys, monkeypatch):
    """Case 7: a scene path that is not Python, or a script with a syntax error, that is binary, or that
    raises, is named in one line, nothing written."""
    script = tmp_path / name
    script.write_text(text)
    monkeypatch.chdir(tmp_path)
    code, _, err = run_cli(capsys, str(script), *QUICK)
    assert_refused(code, err, f"scene script '{script}'", message)
    assert sorted(os.listdir(tmp_path)) == [name]


def test_a_cluster_port_out_of_range_is_refused(capsys):
    """Case 7: `cluster --port -1` (and 70000) is a usage error (exit 2) naming the range, before any cluster."""
    for port in ("-1", "70000"):
        with pytest.raises(SystemExit) as stop:
            cli.main(["cluster", "--device", "cpu", "--port", port])
        assert stop.value.code == 2 and "must be a port number from 0 to 65535" in capsys.readouterr().err


def test_baked_levels_past_memory_are_refused_before_anything_is_allocated(tmp_path, capsys, monkeypatch):
    """Cases 7 and 8: --usd-bake-levels 12 of a 192-triangle cube makes 3.2e9 triangles: refused at once with
    the estimate and the largest level that fits (here, with 1 GB, 6: 400 bytes a baked triangle)."""
    monkeypatch.setattr(sizing, "host_available", lambda: 1e9)
    code, _, err = run_cli(capsys, "cube-waves", *QUICK, "--usd-surface", "baked", "--usd-bake-levels", "12", "--out",
                           str(tmp_path / "c.usda"))
    assert_refused(code, err, "--usd-bake-levels 12 makes 3,221,225,472 triangles and needs about 1,288.5 GB",
                   "the largest that fits is 6")
    code = cli.main(["render", "--mesh", "icosphere", "--level", "1", "--usd-surface", "baked", "--usd-bake-levels",
                     "12", "--device", "cpu", "--out", str(tmp_path / "r.usda")])
    assert code == 2 and "--usd-bake-levels 12 makes 1,342,177,280 triangles" in capsys.readouterr().err
    assert os.listdir(tmp_path) == []


def test_a_frame_count_whose_output_cannot_fit_is_refused_with_the_estimate(tmp_path, capsys):
    """Case 8: frames=100000000 would write about 752 GB (7.5 kB a frame of the 98-vertex cube, HDF5 and USD):
    refused before the first frame, naming the estimate (and the free disk space or memory it exceeds)."""
    code, _, err = run_cli(capsys, "cube-waves", *QUICK, "--set", "frames=100000000", "--out", str(tmp_path / "c.usda"))
    assert_refused(code, err, "100,000,001 frames of 98 points take about", "fewer frames (--set frames=N)")
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("scene, message", [
    ("cube-waves", "dt=1e-09 makes 5.12e+10 time steps to t_end=44"),
    ("sphere-walker", "dt=1e-09 makes"),
])
def test_a_time_step_that_makes_an_absurd_run_is_refused_with_the_estimate(scene, message, tmp_path, capsys):
    """Case 8: dt=1e-9 makes tens of billions of steps: refused before the run is built (the walker before
    it settles)."""
    code, _, err = run_cli(capsys, scene, *QUICK, "--set", "dt=1e-9", "--set", "t_end=auto" if scene == "cube-waves"
                           else "periods=2.2", "--out", str(tmp_path / "c.usda"))
    assert_refused(code, err, message, "more than 1e+09", "--set dt=auto")
    assert os.listdir(tmp_path) == []


def test_the_memory_guard_respects_the_address_space_limit(tmp_path):
    """Case 8: under ulimit -v 6 GB, level 8 (its own estimate 11.1 GB) is refused naming the limit, though the
    machine may have more memory available. The CPU run hides the GPUs; on a GPU machine Warp's start still tries
    the CUDA driver, which cannot map its address space under that limit, and Warp prints its own line ("Warp CUDA
    error 2: out of memory (in function init_cuda_driver ...)") before any of ours: ours is the one other line."""
    def limited():
        resource.setrlimit(resource.RLIMIT_AS, (6 * 2**30, 6 * 2**30))

    run = subprocess.run([sys.executable, "-m", "wavewarp.cli", "run", "starfish", *QUICK, "--set", "level=8", "--out",
                          str(tmp_path / "s.usda")], capture_output=True, text=True, preexec_fn=limited,
                         env={**os.environ, "CUDA_VISIBLE_DEVICES": ""})
    ours = [line for line in run.stderr.splitlines() if not line.startswith("Warp CUDA error")]
    assert run.returncode == 2 and len(ours) == 1, run.stderr
    assert "level=8 makes 1,310,720 triangles and needs about 11.1 GB" in run.stderr
    assert "address-space limit (ulimit -v)" in run.stderr and "the largest level that fits is" in run.stderr


def test_the_memory_guard_reads_the_cgroup_limits(tmp_path):
    """cgroup v2: the smallest memory.max - memory.current over the process's cgroup and those above it ("max":
    none); cgroup v1: memory.limit_in_bytes - memory.usage_in_bytes (its "no limit" is near 2⁶³)."""
    root, membership = tmp_path / "cgroup", tmp_path / "membership"
    for folder, limit, usage in (("", "max", 9e9), ("a", "8000000000", 3e9), ("a/b", "6000000000", 2e9)):
        (root / folder).mkdir(parents=True, exist_ok=True)
        (root / folder / "memory.max").write_text(f"{limit}\n")
        (root / folder / "memory.current").write_text(f"{int(usage)}\n")
    membership.write_text("0::/a/b\n")
    assert sizing.cgroup_left(str(root), str(membership)) == 4e9
    membership.write_text("0::/\n")
    assert sizing.cgroup_left(str(root), str(membership)) is None
    v1 = root / "memory" / "job"
    v1.mkdir(parents=True)
    (v1 / "memory.limit_in_bytes").write_text("2000000000\n")
    (v1 / "memory.usage_in_bytes").write_text("500000000\n")
    (root / "memory" / "memory.limit_in_bytes").write_text(f"{2**63 - 4096}\n")
    membership.write_text("4:cpu,cpuacct:/job\n3:memory:/job\n")
    assert sizing.cgroup_left(str(root), str(membership)) == 1.5e9
    assert sizing.cgroup_left(str(root), str(tmp_path / "missing")) is None
