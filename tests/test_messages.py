"""Messages in the user's terms: the size guard, `auto` values, frames and divisions said rather than
changed silently, path and device errors before a scene is built, no CUDA warning on a CPU run, and
help that lists a scene's parameters."""

import os
import subprocess
import sys

import pytest
import warp as wp

from wavewarp import cli, sizing
from wavewarp.benchmarks import NAMES as BENCHMARKS
from wavewarp.device import resolve_device
from wavewarp.mesh import cube, icosphere, prism
from wavewarp.parameters import SceneError, load_scene, resolve
from wavewarp.scenes import cube_waves, starfish

NO_CUDA = not wp.is_cuda_available()


def refuse_build(monkeypatch, module):
    def build(*args, **kwargs):
        raise AssertionError("the scene was built before its arguments were checked")

    monkeypatch.setattr(module, "build", build)


def test_size_guard_refuses_level_12_before_building(tmp_path, capsys):
    assert cli.main(["run", "starfish", "--device", "cpu", "--set", "level=12", "--out", str(tmp_path / "s.usda")]) == 2
    message = capsys.readouterr().err
    assert "level=12 makes 335,544,320 triangles" in message and "the largest level that fits is" in message
    assert os.listdir(tmp_path) == []


def test_size_guard_names_the_largest_value_that_fits(monkeypatch):
    # available memory exactly what level 5 (divisions 10) needs: 5 (10) fits, 6 (12) does not
    monkeypatch.setattr(sizing, "host_available", lambda: sizing.run_bytes(20 * 4**5))
    sizing.check_run_size("level", 5, icosphere, device="cpu")
    with pytest.raises(ValueError, match=r"level=7 makes 327,680 triangles .* the largest level that fits is 5 \(20,480"):
        sizing.check_run_size("level", 7, icosphere, device="cpu")
    monkeypatch.setattr(sizing, "host_available", lambda: sizing.run_bytes(12 * 10**2))
    with pytest.raises(ValueError, match=r"divisions=16 makes 3,072 triangles .* the largest divisions that fits is 10"):
        sizing.check_run_size("divisions", 16, cube, device="cpu")


def test_size_guard_counts_the_generators_triangles():
    assert sizing.icosphere_triangles(2) == icosphere(1.0, 2).n_triangles
    assert sizing.cube_triangles(6) == cube(1.0, 6).n_triangles
    assert sizing.prism_triangles(6) == prism(1.0, 6).n_triangles


def test_auto_is_accepted_where_zero_means_automatic():
    p = resolve(starfish.Parameters, starfish.QUICK, ["dt=auto", "relax_every=AUTO", "t_end=auto"])
    assert (p.dt, p.relax_every, p.t_end) == (0.0, 0, 0.0)
    walker = load_scene("sphere-walker")
    assert resolve(walker.Parameters, None, ["dt=auto"]).dt == 0.0
    with pytest.raises(SceneError, match="bad value for dt: 'soon' \\(expected a finite number or auto\\)"):
        resolve(starfish.Parameters, None, ["dt=soon"])
    with pytest.raises(SceneError, match="expected an integer\\)"):  # no automatic level
        resolve(starfish.Parameters, None, ["level=auto"])


def test_the_time_step_error_suggests_what_the_command_line_accepts(tmp_path, capsys):
    code = cli.main(["run", "cube-waves", "--quick", "--device", "cpu", "--set", "dt=50", "--out", str(tmp_path / "c.usda")])
    message = capsys.readouterr().err
    assert code != 0 and "exceeds the stability bound" in message and "--set dt=auto" in message


def test_frames_asked_for_are_written_when_the_step_is_automatic():
    p = resolve(starfish.Parameters, starfish.QUICK, ["frames=48"])
    run = starfish.build(p, device="cpu", report=pytest.fail)
    assert run.frames == 48
    assert run.frames * run.steps_per_frame * run.resolved["dt"] == pytest.approx(p.t_end, rel=1e-12)


def test_fewer_frames_are_said(monkeypatch):
    heard = []
    p = resolve(starfish.Parameters, starfish.QUICK, ["frames=48", "dt=0.5"])
    run = starfish.build(p, device="cpu", report=heard.append)
    assert run.frames == 8  # t_end 4 in steps of 0.5
    assert any("8 frames, not the 48 asked for" in line and "--set dt=auto" in line for line in heard)


def test_odd_divisions_are_refused_not_rounded():
    with pytest.raises(SceneError, match=r"bad value for divisions: 5 \(must be even, e.g. 6\)"):
        resolve(cube_waves.Parameters, None, ["divisions=5"])


@pytest.mark.parametrize("out, message", [("/proc/x.usd", "cannot write '/proc/x.usd'"),
                                          ("{tmp}/missing/x.usda", "folder '{tmp}/missing' does not exist"),
                                          ("{tmp}", "it is a folder")])  # fmt: skip
def test_path_errors_name_the_users_path_before_the_scene_is_built(monkeypatch, tmp_path, capsys, out, message):
    refuse_build(monkeypatch, starfish)
    assert cli.main(["run", "starfish", "--quick", "--device", "cpu", "--out", out.format(tmp=tmp_path)]) == 2
    assert message.format(tmp=tmp_path) in capsys.readouterr().err


@pytest.mark.skipif(not NO_CUDA, reason="this machine has CUDA")
def test_cuda_asked_for_without_a_driver_is_one_clear_error(monkeypatch, tmp_path, capsys):
    refuse_build(monkeypatch, starfish)
    assert cli.main(["run", "starfish", "--quick", "--device", "cuda", "--out", str(tmp_path / "s.usda")]) == 2
    assert "device 'cuda' is not available: no NVIDIA CUDA driver or GPU" in capsys.readouterr().err
    with pytest.raises(ValueError, match="no NVIDIA CUDA driver"):
        resolve_device("cuda:0")


def test_a_cpu_run_prints_no_cuda_warning():
    code = "from wavewarp.device import resolve_device; print(resolve_device('cpu'))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.splitlines()[-1] == "cpu"
    assert "CUDA" not in done.stderr


def test_run_scene_help_lists_its_parameters(capsys):
    with pytest.raises(SystemExit) as stop:
        cli.main(["run", "starfish", "--help"])
    assert stop.value.code == 0
    text = capsys.readouterr().out
    assert "--set NAME=VALUE" in text and "level = 4: icosphere level" in text and "dt = auto:" in text
    assert "--quick sets level=3" in text


@pytest.mark.parametrize("name", BENCHMARKS)
def test_each_benchmark_names_itself(name, capsys):
    with pytest.raises(SystemExit) as stop:
        cli.main(["bench", name, "-h"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: wavewarp bench {name}")
