"""A run killed with SIGKILL keeps every completed frame, and --resume continues it bit-identically."""

import json
import os
import subprocess
import sys
import textwrap

import h5py
import numpy as np
from pxr import Usd

from wavewarp.cli import main

ARGS = ["--quick", "--device", "cpu", "--set", "frames=6", "--set", "t_end=8", "--json"]
KILLED_AFTER = 3.9  # the scene's clock: the process dies after writing the first frame past it


def killing_scene(folder) -> str:
    """A scene script: cube-waves, whose process kills itself (SIGKILL) once a frame at t > KILLED_AFTER
    is written, as the OOM killer or a power cut would."""
    path = folder / "killed_cube_waves.py"
    path.write_text(textwrap.dedent(f"""
        import os, signal
        from wavewarp.scenes import cube_waves
        from wavewarp.scenes.cube_waves import NAME, QUICK, Parameters

        def build(p, **options):
            run = cube_waves.build(p, **options)
            advance = run.advance_frame

            def advance_or_die():
                if run.time > {KILLED_AFTER}:
                    os.kill(os.getpid(), signal.SIGKILL)
                advance()

            run.advance_frame = advance_or_die
            return run
    """))
    return str(path)


def summary(capsys, *args):
    code = main(["run", *args])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def test_kill_9_then_resume_gives_the_uninterrupted_run(tmp_path, capsys):
    full = summary(capsys, "cube-waves", *ARGS, "--out", str(tmp_path / "full.usda"))
    killed = subprocess.run([sys.executable, "-m", "wavewarp.cli", "run", killing_scene(tmp_path), *ARGS, "--out",
                             str(tmp_path / "part.usda")], capture_output=True, text=True)  # fmt: skip
    assert killed.returncode == -9, killed.stderr
    with h5py.File(tmp_path / "full_trajectory.h5", "r") as f:
        times = f["frames/time"][...]
    written = int(np.flatnonzero(times > KILLED_AFTER)[0]) + 1  # up to the first frame past KILLED_AFTER
    assert 2 <= written < len(times)
    part = tmp_path / "part_trajectory.h5"
    with h5py.File(part, "r") as f:
        assert f["frames"].attrs["complete"] == written == len(f["frames/time"])
    leftovers = [name for name in os.listdir(tmp_path) if name.startswith(".part.usda.")]
    # the killed process's USD, never renamed into place, and its lock file (no lock is held after a kill)
    assert sorted(name.endswith(".lock") for name in leftovers) == [False, True]
    resumed = summary(capsys, "cube-waves", "--resume", "--device", "cpu", "--json", "--out", str(tmp_path / "part.usda"))
    assert not [name for name in os.listdir(tmp_path) if name.startswith(".part.usda.")]  # removed as stale
    with h5py.File(tmp_path / "full_trajectory.h5", "r") as a, h5py.File(part, "r") as b:
        assert sorted(a["frames"]) == sorted(b["frames"])
        for name in a["frames"]:
            np.testing.assert_array_equal(b["frames"][name][...], a["frames"][name][...], err_msg=name)
        assert json.loads(a.attrs["measurements"]) == json.loads(b.attrs["measurements"])
    for key in set(full) - {"wall_time_s", "outputs"}:
        assert resumed[key] == full[key], key
    stage = Usd.Stage.Open(str(tmp_path / "part.usda"))  # rebuilt from the trajectory: every frame
    assert len(stage.GetPrimAtPath("/World/Shell").GetAttribute("points").GetTimeSamples()) == full["frames"]
