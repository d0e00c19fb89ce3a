"""A sweep killed inside a batch (docs/theory/sweeps.md): with --h5 its batches go on from their worlds'
trajectories and give the results of the sweep that was never stopped, bit for bit (float64, CPU)."""

import concurrent.futures
import json
from dataclasses import replace

import h5py
import numpy as np
import pytest

from wavewarp.batch import WalkerBatch
from wavewarp.quasistatic_batch import QuasiStaticBatch
from wavewarp.sweep import SweepSpec, grid_points, started_batches, sweep
from wavewarp.trajectory import TrajectoryWriter, read_frames
from wavewarp.walker import WalkerRun

FIXED = ("level=1", "periods=0.15", "frames=3", "settle=1", "dtype=float64", "contact_sweeps=2")
SPEC = SweepSpec("sphere-walker", grid={"AC": ["0.1", "0.3"]}, fixed=FIXED, device="cpu", h5=True, deterministic=True)


def one_thread():
    return concurrent.futures.ThreadPoolExecutor(max_workers=1)


def killed_after(monkeypatch, cls, frames: int) -> list:
    """cls.advance_frame raises KeyboardInterrupt (a kill, as Ctrl-C) once `frames` frames have advanced;
    returns the list that counts the frames advanced."""
    monkeypatch.undo()  # any earlier patch
    advance, advanced = cls.advance_frame, []

    def advance_frame(self):
        if len(advanced) == frames:
            raise KeyboardInterrupt
        advanced.append(self.time)
        advance(self)

    monkeypatch.setattr(cls, "advance_frame", advance_frame)
    return advanced


def assert_same_points(a, b, points) -> None:
    """Each point's result (but wall time, the resume's note and which sweep wrote it) and trajectory equal in
    folders a and b."""
    for point in points:
        results = []
        for folder in (a, b):
            with open(folder / "points" / f"{point.name}.json") as f:
                result = json.load(f)
            result.pop("wall_time_s")
            result.pop("invocation")
            result.get("batch", {}).pop("resumed_after_frames", None)
            result.pop("resumed_after_frames", None)
            results.append(result)
        assert results[0] == results[1], point.name
        name = f"{point.name}.h5"
        with h5py.File(a / "points" / name, "r") as f, h5py.File(b / "points" / name, "r") as g:
            assert sorted(f["frames"]) == sorted(g["frames"])
            for name in f["frames"]:
                np.testing.assert_array_equal(g["frames"][name][...], f["frames"][name][...], err_msg=name)
            assert f.attrs["measurements"] == g.attrs["measurements"]


@pytest.mark.parametrize("mechanics", ["overdamped", "inertial"])
def test_a_batch_killed_midway_goes_on_from_its_worlds_trajectories(tmp_path, monkeypatch, mechanics):
    """Killed after one of its 3 frames, the batch of 2 worlds keeps 2 frames a world and no result; the
    rerun (even with another --batch) continues that batch as it was, advances only the 2 frames left, and
    every result and trajectory equals the uninterrupted sweep's (with inertia the velocities matter)."""
    spec = replace(SPEC, fixed=(*FIXED, f"mechanics={mechanics}"))
    points = grid_points(spec)
    sweep(spec, str(tmp_path / "full"), executor=one_thread(), batch=2)
    killed_after(monkeypatch, WalkerBatch, 1)
    with pytest.raises(KeyboardInterrupt):
        sweep(spec, str(tmp_path / "part"), executor=one_thread(), batch=2)
    for point in points:
        assert not (tmp_path / "part" / "points" / f"{point.name}.json").exists()
        assert len(read_frames(tmp_path / "part" / "points" / f"{point.name}.h5")) == 2
    assert started_batches(str(tmp_path / "part"), points) == ([points], [])
    advanced = killed_after(monkeypatch, WalkerBatch, 100)
    rows = sweep(spec, str(tmp_path / "part"), executor=one_thread(), batch=1)
    assert len(advanced) == 2 and [row["status"] for row in rows] == ["done", "done"]
    with open(tmp_path / "part" / "points" / f"{points[0].name}.json") as f:
        assert json.load(f)["batch"] == {"worlds": 2, "world": 0, "resumed_after_frames": 2}
    assert_same_points(tmp_path / "full", tmp_path / "part", points)


def test_a_quasi_static_batch_killed_midway_goes_on_with_its_relaxation_bookkeeping(tmp_path, monkeypatch):
    """buckling-modes (the Fig. S1b sweep's scene) as a batch of 2 worlds, killed after one of its 3 frames:
    the rerun advances the 2 frames left, and the results (mode, relaxation counts, balance) and trajectories
    equal the uninterrupted sweep's."""
    fixed = ("level=2", "frames=3", "t_end=1", "dtype=float64", "adaptive_dt=false", "self_contact=false",
             "relax_iterations=300")  # fmt: skip
    spec = SweepSpec("buckling-modes", grid={"AI": ["10.5", "13.5"]}, fixed=fixed, device="cpu", h5=True,
                     deterministic=True)  # fmt: skip
    points = grid_points(spec)
    sweep(spec, str(tmp_path / "full"), executor=one_thread(), batch=2)
    killed_after(monkeypatch, QuasiStaticBatch, 1)
    with pytest.raises(KeyboardInterrupt):
        sweep(spec, str(tmp_path / "part"), executor=one_thread(), batch=2)
    advanced = killed_after(monkeypatch, QuasiStaticBatch, 100)
    sweep(spec, str(tmp_path / "part"), executor=one_thread(), batch=2)
    assert len(advanced) == 2
    with open(tmp_path / "part" / "points" / f"{points[1].name}.json") as f:
        result = json.load(f)
    assert result["batch"]["resumed_after_frames"] == 2 and result["measurements"]["relax_iterations_mean"] > 0
    assert_same_points(tmp_path / "full", tmp_path / "part", points)


def test_a_single_point_killed_midway_goes_on_from_its_trajectory(tmp_path, monkeypatch):
    """--batch 1: each point is its own run; killed inside the second point, the rerun keeps the first
    point's result, continues the second from its trajectory, and both equal the uninterrupted sweep's."""
    points = grid_points(SPEC)
    sweep(SPEC, str(tmp_path / "full"), executor=one_thread(), batch=1)
    killed_after(monkeypatch, WalkerRun, 3 + 2)  # the first point's 3 frames, then 2 of the second's
    with pytest.raises(KeyboardInterrupt):
        sweep(SPEC, str(tmp_path / "part"), executor=one_thread(), batch=1)
    assert (tmp_path / "part" / "points" / f"{points[0].name}.json").exists()
    assert len(read_frames(tmp_path / "part" / "points" / f"{points[1].name}.h5")) == 3
    advanced = killed_after(monkeypatch, WalkerRun, 100)
    sweep(SPEC, str(tmp_path / "part"), executor=one_thread(), batch=1)
    assert len(advanced) == 1
    with open(tmp_path / "part" / "points" / f"{points[1].name}.json") as f:
        assert json.load(f)["resumed_after_frames"] == 3
    assert_same_points(tmp_path / "full", tmp_path / "part", points)


def test_batches_whose_trajectories_disagree_start_afresh(tmp_path):
    """A point whose trajectory records another batch, or whose batch has a point with a result (or none
    to continue), is dealt into a new batch; a started batch keeps its points together."""
    a, b, c = grid_points(SweepSpec("sphere-walker", grid={"AC": ["0.1", "0.2", "0.3"]}))
    (tmp_path / "points").mkdir()
    for point, batch in ((a, [a, b]), (b, [a, b]), (c, [c, a])):
        with TrajectoryWriter(tmp_path / "points" / f"{point.name}.h5", triangles=np.zeros((1, 3)),
                              rest_positions=np.zeros((3, 3)), series={}, scene="sphere-walker", parameters={},
                              device="cpu", attributes={"sweep_batch": json.dumps([p.name for p in batch])}) as writer:  # fmt: skip
            writer.add_frame(0.0, {})
    assert started_batches(str(tmp_path), [a, b, c]) == ([[a, b]], [c])
    assert started_batches(str(tmp_path), [b, c]) == ([], [b, c])  # a has its result


def test_a_trajectory_resumed_after_fewer_frames_is_cut_there(tmp_path):
    """resume_frames: the frames beyond it are cut (a world of a batch killed one frame ahead of another)
    and the next frame follows them."""
    path = tmp_path / "t.h5"
    options = dict(triangles=np.zeros((1, 3)), rest_positions=np.zeros((3, 3)), series={"c": (3,)}, scene="s",
                   parameters={}, device="cpu")  # fmt: skip
    with TrajectoryWriter(path, **options) as writer:
        for k in range(3):
            writer.add_frame(float(k), {"c": np.full(3, k)})
    with TrajectoryWriter(path, resume=True, resume_frames=2, **options) as writer:
        assert writer.frames == 2
        writer.add_frame(5.0, {"c": np.full(3, 5.0)})
    frames = read_frames(path)
    assert [t for t, _ in frames] == [0.0, 1.0, 5.0] and frames[-1][1]["c"].tolist() == [5.0] * 3
