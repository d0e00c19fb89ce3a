"""The README's Python tour runs as written, on coarser meshes and a shorter drop."""

import math
import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"
COARSER = [  # (README text, what the test runs instead); each must be found, so the tour stays covered
    ("ww.icosphere(radius=2.0, level=4)", "ww.icosphere(radius=2.0, level=2)"),
    ('mesh = ww.load("shell.obj")', 'ww.save(box, "shell.obj"); mesh = ww.load("shell.obj")'),
    ("ww.sample_points(sphere, triangle_ids, vw)",
     "ww.sample_points(sphere, np.array([0, 7]), np.array([[0.2, 0.3], [0.1, 0.1]]))"),
    ("Shell(icosphere(1.0, 3)", "Shell(icosphere(1.0, 1)"),
    ("run.run_until(20.0)", "run.run_until(1.0)"),
    ('["noise=0.01"]', '["noise=0.01", "level=1", "periods=0.1", "frames=1", "settle=1"]'),
    ('seeds=[0, 1, 2], device="cuda")', 'seeds=[0, 1, 2], device="cpu")'),
]


def tour_blocks() -> list[str]:
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)
    source = "\n".join(blocks)
    for written, coarser in COARSER:
        assert written in source, f"the README no longer says {written!r}: update COARSER"
        source = source.replace(written, coarser)
    return source


def test_readme_tour_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    names = {"np": np}
    exec(compile(tour_blocks(), str(README), "exec"), names)
    surface = names["s"]
    assert math.isclose(surface.integrate(surface.gauss_curvature), 4 * math.pi, rel_tol=1e-3)  # Gauss–Bonnet, to quadrature error
    assert (tmp_path / "finer.ply").exists()
    stepped, pulse = names["state"].c.numpy(), names["c0"]
    assert np.isfinite(stepped).all() and not np.array_equal(stepped, pulse)
    assert names["batch"].worlds == 3 and names["result"]["status"] == "done"
