"""Outputs that cannot be clobbered and survive faults (docs/theory/scenes.md "Outputs"; issue 57, "Restarts and
outputs" 2, 6 and 9): one writer per file (a lock), no file replaced without --overwrite, SIGINT and SIGTERM
(exit 130, 143) even before the second frame, a full disk that keeps the frames written for a resume, and an
HDF5 file that describes itself."""

import errno
import hashlib
import json
import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
from trajectories import assert_refused, assert_same_trajectory, run_cli, waiting_scene

from wavewarp.quasistatic import QuasiStaticWaveRun
from wavewarp.schema import DATASETS

QUICK = ["--quick", "--device", "cpu"]
CUBE = ["cube-waves", *QUICK, "--set", "t_end=auto", "--set", "frames=6"]


HANG_GUARD_S = 600  # a test that waits on another process fails after this (a guard against hanging, no limit)


def interruptible() -> None:
    """In the child before it starts: SIGINT back to its default, as at a terminal (a suite started in the background
    of a non-interactive shell ignores SIGINT, and its children inherit that)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.fixture
def waiting_runs(tmp_path):
    """start(name): `start_waiting_run` in tmp_path; any still running at the end is killed."""
    started = []

    def start(name):
        started.append(start_waiting_run(tmp_path, name))
        return started[-1]

    yield start
    for process in started:
        if process.poll() is None:
            process.kill()
            process.communicate()


def start_waiting_run(folder, name: str) -> subprocess.Popen:
    """`wavewarp run` of the waiting scene into FOLDER/NAME.usda and FOLDER/NAME.h5 in its own process, returned
    once its first frame is written (the scene says so: FOLDER/ready.PID)."""
    out, h5 = folder / f"{name}.usda", folder / f"{name}.h5"
    process = subprocess.Popen([sys.executable, "-m", "wavewarp.cli", "run", waiting_scene(folder), *QUICK, "--out",
                                str(out), "--h5", str(h5)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=interruptible)
    start = time.monotonic()
    while not (folder / f"ready.{process.pid}").exists():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() - start < HANG_GUARD_S, "the waiting run wrote no frame"
        time.sleep(0.05)
    return process


def test_a_second_run_on_the_same_output_is_refused_and_the_first_keeps_its_file(tmp_path, capsys, waiting_runs):
    """Case 2: while a run writes run.usda and run.h5, a second run on them (even with --overwrite) is refused in
    one line naming the first's process; the first then writes all its frames into its file."""
    first = waiting_runs("run")
    for extra in ([], ["--overwrite"]):
        code, _, err = run_cli(capsys, "cube-waves", *QUICK, "--out", str(tmp_path / "run.usda"), "--h5",
                               str(tmp_path / "run.h5"), *extra)
        assert_refused(code, err, "run.usda' is being written by process", str(first.pid))
    (tmp_path / "go").touch()
    out, err = first.communicate(timeout=HANG_GUARD_S)
    assert first.returncode == 0, err
    with h5py.File(tmp_path / "run.h5", "r") as f:
        assert f["frames"].attrs["complete"] == len(f["frames/time"]) == 4 and "measurements" in f.attrs
    assert not [name for name in os.listdir(tmp_path) if name.endswith(".lock")]


def test_an_existing_file_is_replaced_only_with_overwrite(tmp_path, capsys):
    """Case 2: a file at an output's path (here a note, no wavewarp file) is refused without --overwrite,
    naming the flag, and left as it was; with --overwrite the run replaces it."""
    note = tmp_path / "run.h5"
    note.write_text("my notes")
    args = ["cube-waves", *QUICK, "--out", str(tmp_path / "run.usda"), "--h5", str(note)]
    assert_refused(*run_cli(capsys, *args)[::2], f"'{note}' exists: --overwrite replaces it")
    assert note.read_text() == "my notes" and sorted(os.listdir(tmp_path)) == ["run.h5"]
    code, _, err = run_cli(capsys, *args, "--overwrite")
    assert code == 0, err
    with h5py.File(note, "r") as f:
        assert f.attrs["scene"] == "cube-waves"


def test_sigterm_and_sigint_exit_143_and_130_keeping_the_first_frame(tmp_path, waiting_runs):
    """Case 6: a run stopped by SIGTERM (SIGINT) while it computes its second frame exits 143 (130) by
    convention, in one line and no traceback, its trajectory holding the first frame, its USD file written."""
    stopped = {}
    for name, stop in (("term", signal.SIGTERM), ("int", signal.SIGINT)):
        process = waiting_runs(name)
        process.send_signal(stop)
        stopped[name] = (process, *process.communicate(timeout=HANG_GUARD_S))
    for name, code in (("term", 143), ("int", 130)):
        process, out, err = stopped[name]
        assert process.returncode == code and "Traceback" not in err, err
        assert "interrupted; kept 1 frames" in out
        with h5py.File(tmp_path / f"{name}.h5", "r") as f:
            assert f["frames"].attrs["complete"] == 1
        assert (tmp_path / f"{name}.usda").exists()


def test_an_interrupt_before_the_second_frame_measures_what_there_is(tmp_path, capsys, monkeypatch):
    """Case 6: Ctrl-C or SIGTERM during the first frame's steps of an oocyte (whose arrival times need two
    samples) exits 130 or 143 with the first frame kept, not "argmax of an empty sequence"."""
    def stop(self):
        if self.stop is signal.SIGINT:
            raise KeyboardInterrupt
        os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(QuasiStaticWaveRun, "advance_frame", stop)
    for sent, code in ((signal.SIGINT, 130), (signal.SIGTERM, 143)):
        monkeypatch.setattr(QuasiStaticWaveRun, "stop", sent, raising=False)
        h5 = tmp_path / f"{sent.name}.h5"
        result, out, err = run_cli(capsys, "starfish", *QUICK, "--out", str(tmp_path / f"{sent.name}.usda"),
                                   "--h5", str(h5), "--json")
        assert result == code and "argmax" not in err and "Traceback" not in err, err
        summary = json.loads(out)
        assert summary["interrupted"] and summary["frames"] == 1 and summary["wave_speed"] is None
        with h5py.File(h5, "r") as f:
            assert f["frames"].attrs["complete"] == 1


def test_a_full_disk_keeps_the_frames_written_and_the_run_resumes(tmp_path, capsys, monkeypatch):
    """ENOSPC while the fifth frame is written (its time in, its positions not): the run stops with exit 1 and
    one line saying so and how to go on; the file holds the four frames before it, and a resume once there is
    room gives the uninterrupted run's file bit for bit."""
    full, part = tmp_path / "full.h5", tmp_path / "part.h5"
    assert run_cli(capsys, *CUBE, "--out", str(tmp_path / "full.usda"), "--h5", str(full))[0] == 0
    write = h5py.Dataset.__setitem__

    def full_disk(dataset, index, value):
        if dataset.name == "/frames/positions" and index == 4:
            raise OSError(errno.ENOSPC, "No space left on device")
        write(dataset, index, value)

    monkeypatch.setattr(h5py.Dataset, "__setitem__", full_disk)
    code, _, err = run_cli(capsys, *CUBE, "--out", str(tmp_path / "part.usda"), "--h5", str(part))
    monkeypatch.undo()
    assert code == 1 and err.count("\n") == 1 and "Traceback" not in err, err
    assert "No space left on device" in err and "--resume" in err and "kept the 4 frames before it" in err
    with h5py.File(part, "r") as f:
        assert f["frames"].attrs["complete"] == 4 and "measurements" not in f.attrs
    code, _, err = run_cli(capsys, "cube-waves", "--resume", "--device", "cpu", "--h5", str(part), "--out",
                           str(tmp_path / "part.usda"), "--overwrite")
    assert code == 0, err
    assert_same_trajectory(full, part, unlike=("resumed_by", "command_line"))


def sha256(array, dtype) -> str:
    """The provenance's digest as docs/theory/scenes.md states it: SHA-256 of repr(shape) then the
    little-endian bytes."""
    values = np.ascontiguousarray(np.asarray(array, dtype=np.dtype(dtype).newbyteorder("<")))
    return hashlib.sha256(repr(values.shape).encode() + values.tobytes()).hexdigest()


def test_the_trajectory_describes_itself_and_its_run(tmp_path, capsys):
    """Case 9: every dataset carries units and a one-line description; the root attributes hold the seed,
    the command line, the mesh's source, the digests of the stored mesh and rest positions, the frames
    planned and the version."""
    h5 = tmp_path / "run.h5"
    args = ["cube-waves", *QUICK, "--seed", "5", "--out", str(tmp_path / "run.usda"), "--h5", str(h5)]
    assert run_cli(capsys, *args)[0] == 0
    with h5py.File(h5, "r") as f:
        datasets = []
        f.visititems(lambda name, item: datasets.append((name, item)) if isinstance(item, h5py.Dataset) else None)
        assert {"frames/time", "frames/positions", "mesh/triangles"} <= {name for name, _ in datasets}
        for name, dataset in datasets:
            assert dataset.attrs["units"] and dataset.attrs["description"], name
            assert "\n" not in dataset.attrs["description"], name
            if name in DATASETS:
                assert (dataset.attrs["units"], dataset.attrs["description"]) == DATASETS[name]
        assert f.attrs["seed"] == 5 and f.attrs["command_line"] == "wavewarp run " + " ".join(args)
        assert f.attrs["mesh_source"] == "the scene's own mesh" and f.attrs["frames_planned"] == 4
        assert f.attrs["mesh_sha256"] == sha256(f["mesh/triangles"][...], np.int32)
        assert f.attrs["rest_positions_sha256"] == sha256(f["mesh/rest_positions"][...], np.float64)
        assert f.attrs["wavewarp_version"] and f.attrs["time_unit"]
