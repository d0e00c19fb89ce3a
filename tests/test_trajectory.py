"""HDF5 trajectories: docs/theory/scenes.md schema, atomic writes, Ctrl-C keeps frames, resume appends."""

import json
import os

import h5py
import numpy as np
import pytest

from wavewarp.mesh import icosphere
from wavewarp.trajectory import TrajectoryWriter, last_frame

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


def test_interrupt_keeps_frames_and_errors_leave_nothing(tmp_path):
    path = tmp_path / "run.h5"
    with pytest.raises(KeyboardInterrupt):
        with writer(path) as w:
            w.add_frame(0.0, frame(0))
            raise KeyboardInterrupt
    assert last_frame(path)["frames"] == 1
    other = tmp_path / "crash.h5"
    with pytest.raises(RuntimeError):
        with writer(other) as w:
            w.add_frame(0.0, frame(0))
            raise RuntimeError("solver failed")
    assert os.listdir(tmp_path) == ["run.h5"]  # no partial file, no temporary left
    with pytest.raises(ValueError, match="non-finite concentration"):
        with writer(other) as w:
            w.add_frame(0.0, {"positions": MESH.vertices, "concentration": np.full(V, np.nan)})
    assert not other.exists()


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
