"""HDF5 trajectories: docs/theory/scenes.md schema, durable frame by frame, resume appends."""

import json
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

from wavewarp.mesh import icosphere
from wavewarp.trajectory import TrajectoryWriter, last_frame, read_frames

MESH = icosphere(1.0, 1)
V = MESH.n_vertices


def writer(path, resume=False, parameters=None):
    return TrajectoryWriter(path, triangles=MESH.triangles, rest_positions=MESH.vertices,
                            series={"positions": (V, 3), "concentration": (V,)}, scene="test",
                            parameters=parameters or {"AC": 1.5}, device="cpu", resume=resume)  # fmt: skip


def frame(k):
    return dict(positions=MESH.vertices * (1 + 0.01 * k), concentration=np.full(V, 0.1 * k))


def test_schema_and_attributes(tmp_path):
    path = tmp_path / "run.h5"
    with writer(path) as w:
        for k in range(3):
            w.add_frame(0.5 * k, frame(k))
    with h5py.File(path, "r") as f:
        np.testing.assert_array_equal(f["mesh/triangles"][...], MESH.triangles)
        np.testing.assert_array_equal(f["mesh/rest_positions"][...], MESH.vertices)
        np.testing.assert_array_equal(f["frames/time"][...], [0.0, 0.5, 1.0])
        assert f["frames/positions"].shape == (3, V, 3) and f["frames/concentration"].shape == (3, V)
        np.testing.assert_allclose(f["frames/concentration"][2], 0.2)
        assert f.attrs["scene"] == "test" and json.loads(f.attrs["parameters"]) == {"AC": 1.5}
        assert f.attrs["device"] == "cpu" and f.attrs["wavewarp_version"]


def test_every_completed_frame_is_kept_and_nothing_before_the_first(tmp_path):
    path = tmp_path / "run.h5"
    with pytest.raises(KeyboardInterrupt):
        with writer(path) as w:
            w.add_frame(0.0, frame(0))
            raise KeyboardInterrupt
    assert last_frame(path)["frames"] == 1
    other = tmp_path / "crash.h5"
    with pytest.raises(RuntimeError):
        with writer(other) as w:
            raise RuntimeError("solver failed before the first frame")
    assert sorted(os.listdir(tmp_path)) == ["run.h5"]  # no file, no temporary left
    with pytest.raises(RuntimeError):
        with writer(other) as w:
            w.add_frame(0.0, frame(0))
            w.add_frame(1.0, frame(1))
            raise RuntimeError("solver failed")
    assert last_frame(other)["frames"] == 2
    with pytest.raises(ValueError, match="non-finite concentration"):
        with writer(path) as w:
            w.add_frame(0.0, {"positions": MESH.vertices, "concentration": np.full(V, np.nan)})
    assert last_frame(path)["frames"] == 1  # the older file is untouched


def test_the_file_has_its_name_from_the_first_frame(tmp_path):
    path = tmp_path / "run.h5"
    with writer(path) as w:
        assert not path.exists()
        w.add_frame(0.0, frame(0))
        reader = ("import h5py, sys; f = h5py.File(sys.argv[1], 'r', locking=False); "
                  "print(f['frames'].attrs['complete'], len(f['frames/time']))")  # as after a kill -9 here
        seen = subprocess.run([sys.executable, "-c", reader, str(path)], capture_output=True, text=True)
        assert seen.stdout.split() == ["1", "1"], seen.stderr
        w.add_frame(1.0, frame(1))
    assert sorted(os.listdir(tmp_path)) == ["run.h5"]


def test_a_half_written_frame_is_cut_on_resume(tmp_path):
    path = tmp_path / "run.h5"
    with writer(path) as w:
        for k in range(3):
            w.add_frame(float(k), frame(k))
    with h5py.File(path, "r+") as f:  # as if killed while writing frame 2: its positions in, its count not
        f["frames"].attrs["complete"] = 2
        f["frames/concentration"].resize((2, V))
    times = [t for t, _ in read_frames(path)]
    assert times == [0.0, 1.0] and last_frame(path)["time"] == 1.0
    with writer(path, resume=True) as w:
        w.add_frame(2.0, frame(2))
    with h5py.File(path, "r") as f:
        assert f["frames"].attrs["complete"] == 3
        assert all(len(f["frames"][name]) == 3 for name in f["frames"])
        np.testing.assert_array_equal(f["frames/positions"][2], frame(2)["positions"])


def test_a_series_newer_than_the_file_reads_nan_before_the_resume(tmp_path):
    path = tmp_path / "run.h5"
    with writer(path) as w:
        w.add_frame(0.0, frame(0))
    newer = TrajectoryWriter(path, triangles=MESH.triangles, rest_positions=MESH.vertices,
                             series={"positions": (V, 3), "concentration": (V,), "count_relaxations": ()},
                             scene="test", parameters={}, device="cpu", resume=True)  # fmt: skip
    with newer as w:
        w.add_frame(1.0, {**frame(1), "count_relaxations": np.array(7.0)})
    counts = [f["count_relaxations"] for _, f in read_frames(path)]
    assert np.isnan(counts[0]) and counts[1] == 7.0


def test_stale_temporaries_of_dead_processes_are_removed(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    stale = tmp_path / f".run.h5.{int(dead.stdout)}.abc.tmp.h5"
    stale.write_bytes(b"frames of a killed run")
    alive = tmp_path / f".run.h5.{os.getppid()}.abc.tmp.h5"  # a running process's: kept
    alive.write_bytes(b"")
    with writer(tmp_path / "run.h5") as w:
        w.add_frame(0.0, frame(0))
    assert sorted(os.listdir(tmp_path)) == [alive.name, "run.h5"]


def test_resume_appends_to_the_same_file(tmp_path):
    path = tmp_path / "run.h5"
    with writer(path) as w:
        for k in range(2):
            w.add_frame(float(k), frame(k))
    last = last_frame(path)
    assert last["time"] == 1.0 and last["frames"] == 2
    np.testing.assert_allclose(last["positions"], frame(1)["positions"])
    with writer(path, resume=True) as w:
        w.add_frame(2.0, frame(2))
    with h5py.File(path, "r") as f:
        np.testing.assert_array_equal(f["frames/time"][...], [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="holds scene 'test'"):
        TrajectoryWriter(path, triangles=MESH.triangles, rest_positions=MESH.vertices, series={}, scene="other",
                         parameters={}, device="cpu", resume=True).__enter__()  # fmt: skip
    with h5py.File(path, "r") as f:
        assert len(f["frames/time"]) == 3  # a refused resume changes nothing


def test_bad_paths_are_refused(tmp_path):
    with pytest.raises(ValueError, match="must end in .h5"):
        writer(tmp_path / "run.txt")
    with pytest.raises(ValueError, match="does not exist"):
        writer(tmp_path / "missing" / "run.h5").__enter__()
