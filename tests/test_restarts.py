"""Restart files that refuse the wrong run (docs/theory/scenes.md "Resume"; issue 57, "Restarts and outputs" 1, 3
and 4): a resume continues only the run its trajectory holds (seed, mesh, rest shape), from the frames its data
hold, and gives the uninterrupted run's file bit for bit, its times and measurements included; a finished run's
file is never rewritten."""

import json

import h5py
from trajectories import assert_refused, assert_same_trajectory, file_state, killed_copy, run_cli

from wavewarp.mesh import icosphere, save

# cube-waves on 4 divisions to the scene's own end: 3 relaxations a frame, and the arrival-time measurements
# (eikonal_deviation, ...) that sample every relaxation have a value
CUBE = ["cube-waves", "--quick", "--device", "cpu", "--set", "t_end=auto", "--set", "frames=6"]
# a starfish whose rest shape the seed perturbs
NOISY = ["starfish", "--quick", "--device", "cpu", "--set", "level=2", "--set", "frames=2", "--set", "noise=1e-3"]


def test_a_resumed_run_equals_the_uninterrupted_run_bit_for_bit(tmp_path, capsys):
    """Case 3: the times (summed step by step live) and the measurements (the arrival times sample every
    relaxation, three a frame here) of a run killed after 3 of its 7 frames and resumed are the uninterrupted
    run's, bit for bit; so is every other dataset and attribute."""
    full, part = tmp_path / "full.h5", tmp_path / "part.h5"
    code, out, err = run_cli(capsys, *CUBE, "--json", "--out", str(tmp_path / "full.usda"), "--h5", str(full))
    assert code == 0, err
    assert json.loads(out)["eikonal_deviation"] is not None  # a measurement of the arrival times is compared
    with h5py.File(full, "r") as f:
        assert f["frames/relaxation_count"][-1] == 3
    killed_copy(full, part, keep=3)
    code, _, err = run_cli(capsys, "cube-waves", "--resume", "--device", "cpu", "--h5", str(part), "--out",
                           str(tmp_path / "part.usda"))
    assert code == 0, err
    assert_same_trajectory(full, part)
    with h5py.File(part, "r") as f:
        assert json.loads(f.attrs["resumed_by"])[0].startswith("wavewarp run cube-waves --resume")


def test_a_finished_run_is_never_rewritten(tmp_path, capsys):
    """Case 3: --resume of a finished run says so and exits 0, its file untouched."""
    h5 = tmp_path / "run.h5"
    assert run_cli(capsys, *CUBE, "--out", str(tmp_path / "run.usda"), "--h5", str(h5))[0] == 0
    before = file_state(h5)
    code, out, err = run_cli(capsys, "cube-waves", "--resume", "--device", "cpu", "--h5", str(h5), "--out",
                             str(tmp_path / "again.usda"))
    assert code == 0 and "holds the finished run (7 frames): nothing to resume" in out, err
    assert file_state(h5) == before and not (tmp_path / "again.usda").exists()


def test_a_resume_takes_the_stored_seed_and_refuses_another(tmp_path, capsys):
    """Case 1: a run with --seed 3 (its rest shape perturbed by it) resumes without --seed into the
    uninterrupted run; --resume --seed 7 is refused in one line naming the seed, the file untouched."""
    full, part = tmp_path / "full.h5", tmp_path / "part.h5"
    assert run_cli(capsys, *NOISY, "--seed", "3", "--out", str(tmp_path / "full.usda"), "--h5", str(full))[0] == 0
    killed_copy(full, part, keep=2)
    before = file_state(part)
    resume = ["starfish", "--resume", "--device", "cpu", "--h5", str(part), "--out", str(tmp_path / "part.usda")]
    assert_refused(*run_cli(capsys, *resume, "--seed", "7")[::2], "it ran with --seed 3, not 7", "--seed 3")
    assert file_state(part) == before
    code, _, err = run_cli(capsys, *resume)
    assert code == 0, err
    assert_same_trajectory(full, part)


def test_a_resume_refuses_a_mesh_with_one_vertex_moved(tmp_path, capsys):
    """Case 1: the --mesh file of a resume with one vertex moved by 2 % of the radius is another run."""
    ball = icosphere(25.0, 2)
    moved = ball.vertices.copy()
    moved[7] *= 1.02
    save(ball, tmp_path / "ball.obj")
    save(type(ball)(moved, ball.triangles), tmp_path / "moved.obj")
    h5 = tmp_path / "run.h5"
    args = ["starfish", "--quick", "--device", "cpu", "--set", "frames=2", "--h5", str(h5), "--out",
            str(tmp_path / "run.usda")]
    assert run_cli(capsys, *args, "--mesh", str(tmp_path / "ball.obj"))[0] == 0
    killed_copy(h5, tmp_path / "part.h5", keep=1)
    before = file_state(tmp_path / "part.h5")
    code, _, err = run_cli(capsys, "starfish", "--resume", "--device", "cpu", "--h5", str(tmp_path / "part.h5"),
                           "--mesh", str(tmp_path / "moved.obj"), "--out", str(tmp_path / "part.usda"))
    assert_refused(code, err, "differs from this run's", f"--mesh {tmp_path / 'ball.obj'}")
    assert file_state(tmp_path / "part.h5") == before


def test_a_frame_count_beyond_the_data_is_refused(tmp_path, capsys):
    """Case 4: a file whose /frames count says 99 while its datasets hold 4 is refused, not padded with NaN."""
    h5 = tmp_path / "run.h5"
    assert run_cli(capsys, *CUBE, "--set", "frames=3", "--out", str(tmp_path / "run.usda"), "--h5", str(h5))[0] == 0
    with h5py.File(h5, "r+") as f:
        f["frames"].attrs["complete"] = 99
        del f.attrs["measurements"]
    before = file_state(h5)
    code, _, err = run_cli(capsys, "cube-waves", "--resume", "--device", "cpu", "--h5", str(h5), "--out",
                           str(tmp_path / "again.usda"))
    assert_refused(code, err, "counts 99 complete frames", "its datasets hold 4")
    assert file_state(h5) == before


def test_a_file_that_is_no_trajectory_is_a_one_line_error(tmp_path, capsys):
    """Case 4: a trajectory without `parameters`, and a file that is not HDF5, are refused in one line."""
    h5 = tmp_path / "run.h5"
    assert run_cli(capsys, *CUBE, "--set", "frames=1", "--out", str(tmp_path / "run.usda"), "--h5", str(h5))[0] == 0
    with h5py.File(h5, "r+") as f:
        del f.attrs["parameters"]
    resume = ["cube-waves", "--resume", "--device", "cpu", "--out", str(tmp_path / "again.usda"), "--h5"]
    assert_refused(*run_cli(capsys, *resume, str(h5))[::2], "holds no run parameters")
    (tmp_path / "notes.h5").write_text("not an HDF5 file")
    assert_refused(*run_cli(capsys, *resume, str(tmp_path / "notes.h5"))[::2], "cannot read", "as an HDF5 trajectory")
