"""The scenes' figures (wavewarp/figures.py): the rendered frame's smooth limit surface and the run's
colour scale, the kymograph's diverging limits, and figures that say in the plot what they lack."""

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from wavewarp.driver import simulate
from wavewarp.figures import (SmoothSurface, arrival_map_figure, frame_figure, frame_png, imprint_figure,
                              kymograph_figure, locomotion_figure)
from wavewarp.geometry import sample_points
from wavewarp.mesh import cube, icosphere, prism
from wavewarp.parameters import load_scene
from wavewarp.unfolding import prism_faces, prism_fronts

UNIT = "nondimensional time units (test)"


class Frames:
    """A writer that keeps every frame's control concentrations (what the USD file colours)."""

    def __init__(self):
        self.frames = []

    def __enter__(self):
        return self

    def __exit__(self, *error):
        return False

    def add_frame(self, time, frame):
        self.frames.append((time, {name: np.array(value) for name, value in frame.items()}))


def texts(fig) -> str:
    return " ".join(text.get_text().replace("\u00a0", " ") for ax in fig.axes for text in ax.texts)


def tiny_starfish():
    module = load_scene("starfish")
    return module.build(replace(module.Parameters(), level=2, frames=3, t_end=1.5), device="cpu", report=lambda m: None)


def test_frame_colours_on_the_runs_range_over_every_frame_also_after_a_resume(tmp_path):
    run, frames = tiny_starfish(), Frames()
    simulate(run, [frames], figures_stem=str(tmp_path / "run"))
    fields = np.concatenate([frame["concentration"] for _, frame in frames.frames]).astype(np.float64)
    expected = np.percentile(fields, [0.5, 99.5])
    assert len(frames.frames) == 4 and (tmp_path / "run_frame.png").is_file()
    assert frame_png(run, tmp_path / "frame.png") == pytest.approx(expected, rel=1e-12)
    resumed = tiny_starfish()  # every stored frame replayed through record(stored=True)
    simulate(resumed, [], replay=frames.frames)
    assert frame_png(resumed, tmp_path / "resumed.png") == pytest.approx(expected, rel=1e-12)


def test_the_smooth_frame_draws_points_of_the_limit_surface_and_its_field(rng):
    mesh = icosphere(1.0, 2)
    x = mesh.vertices * (1.0 + 0.05 * rng.standard_normal((mesh.n_vertices, 1)))
    c = rng.standard_normal(mesh.n_vertices)
    run = SimpleNamespace(name="test", mesh=mesh, snapshot=(1.0, x, c), concentrations=[c, 2 * c], time_unit=UNIT,
                          p=SimpleNamespace(radius=1.0))  # fmt: skip
    surface = SmoothSurface(mesh, levels=1)
    fig, _, points = frame_figure(run, surface)
    _, values = surface(x, c)
    children = surface.triangles.reshape(-1, 4, 3)[:, 0]  # child 4t: (corner 1, edge 1-2, edge 3-1) of t
    triangles = np.arange(mesh.n_triangles)
    as_points = np.column_stack([c, np.zeros((len(c), 2))])  # the field as the x coordinate of a surface
    for column, vw in ((0, (0.0, 0.0)), (1, (0.5, 0.0)), (2, (0.0, 0.5))):
        parameters = np.tile(vw, (mesh.n_triangles, 1))
        exact = sample_points(mesh, triangles, parameters, x)
        np.testing.assert_allclose(points[children[:, column]], exact, atol=1e-12)
        field = sample_points(mesh, triangles, parameters, as_points)[:, 0]
        np.testing.assert_allclose(values[children[:, column]], field, atol=1e-12)
    assert surface.n_vertices == mesh.n_vertices + len(mesh.edges)


def kymograph_run(curvature, R=10.0):
    """A synthetic oocyte run whose profiles hold 1/H = R / (H R) per frame."""
    with np.errstate(divide="ignore"):
        profiles = [(0.5 * k, (R / row, 0.0)) for k, row in enumerate(np.asarray(curvature, dtype=float))]
    return SimpleNamespace(name="test", profiles=profiles, size=R, p=SimpleNamespace(radius=R), time_unit=UNIT)


def test_kymograph_limits_are_symmetric_about_the_sphere_and_show_negative_curvature():
    curvature = np.ones((10, 90))  # H R: 1 on the rest sphere
    curvature[:, 10:19] = -0.8  # a tenth everted
    curvature[:, 40:49] = 1.5
    curvature[3, 60] = 0.0  # flat: 1/H infinite
    curvature[5, 70] = -5.0  # one cell below the 0.5 percentile
    fig, limits = kymograph_figure(kymograph_run(curvature))
    assert limits == pytest.approx((-0.8, 2.8))  # 1 ± 1.8, 1.8 = |-0.8 - 1|
    shown = fig.axes[0].collections[0]
    assert shown.get_clim() == pytest.approx(limits) and shown.colorbar.extend == "min"
    assert "time t in " + UNIT in fig.axes[0].get_ylabel().replace("\n", " ")
    fig, limits = kymograph_figure(kymograph_run(curvature[:1]))
    assert limits is None and "at least 2 frames" in texts(fig) and "recorded 1" in texts(fig)


def box_run(mesh, origin, size=20.0, time=4.0):
    """A box wave run whose wave has reached no vertex yet (every arrival 0)."""
    return SimpleNamespace(name="test", mesh=mesh, origin=np.asarray(origin, dtype=float), size=size, time=time,
                           arrival=SimpleNamespace(time=np.zeros(mesh.n_vertices)), time_unit=UNIT,
                           p=SimpleNamespace(gamma=1.0, width=math.sqrt(2.0), origin="face", edge=size))  # fmt: skip


def test_arrival_and_imprint_figures_without_an_arrival_say_so_and_how_long_to_run():
    # the cube's net about the top face reaches √(1.5² + 0.5²) L = 31.6 from its centre; with 4 pulse
    # widths (4 √2) past it: 37.3, rounded up to 40
    fig = arrival_map_figure(box_run(cube(20.0, 4), (0.0, 0.0, 10.0)))
    assert "has reached 0 of the net's" in texts(fig) and "--set t_end=40" in texts(fig)
    fig = arrival_map_figure(box_run(cube(20.0, 4), (10.0, 0.0, 10.0)))  # on an edge: no single face
    assert "No net to unfold" in texts(fig)
    # from the cap centre the farthest point of the opposite cap is (1 + 1/√3) L = 31.5 away: 37.2, so 40
    fig = imprint_figure(box_run(prism(20.0, 4), (0.0, 0.0, 10.0)), prism_faces, prism_fronts)
    assert "has not reached the bottom face" in texts(fig) and "--set t_end=40" in texts(fig)


def test_locomotion_with_fewer_than_two_samples_says_so():
    trace = np.zeros((1, 8))
    fig = locomotion_figure([("walker", True, trace, (1.0, 0.0, 0.0), 1.0)])
    assert "No run has 2 samples" in texts(fig)
