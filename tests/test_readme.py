"""The README's tour and the user guide's examples run as written, on coarser meshes and a shorter drop."""

import math
import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
README, GUIDE = ROOT / "README.md", ROOT / "docs" / "guide.md"
COARSER = {  # per page: (text as written, what the test runs instead); each must be found, so the tour stays covered
    README: [
        ("ww.icosphere(radius=2.0, level=4)", "ww.icosphere(radius=2.0, level=2)"),
    ],
    GUIDE: [
        ("ww.icosphere(radius=2.0, level=4)", "ww.icosphere(radius=2.0, level=2)"),
        ('mesh = ww.load("shell.obj")', 'ww.save(box, "shell.obj"); mesh = ww.load("shell.obj")'),
        ("ww.sample_points(sphere, triangle_ids, vw)",
         "ww.sample_points(sphere, np.array([0, 7]), np.array([[0.2, 0.3], [0.1, 0.1]]))"),
        ("Shell(icosphere(1.0, 3)", "Shell(icosphere(1.0, 1)"),
        ("run.run_until(20.0)", "run.run_until(1.0)"),
        ('["noise=0.01"]', '["noise=0.01", "level=1", "periods=0.1", "frames=1", "settle=1"]'),
        ('seeds=[0, 1, 2], device="cuda")', 'seeds=[0, 1, 2], device="cpu")'),
    ],
}


def tour_blocks(page: Path) -> str:
    """The ```python blocks of `page` in order, as one program, with COARSER's replacements."""
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(), re.S)
    source = "\n".join(blocks)
    for written, coarser in COARSER[page]:
        assert written in source, f"{page.relative_to(ROOT)} no longer says {written!r}: update COARSER"
        source = source.replace(written, coarser)
    return source


def run_page(page: Path) -> dict:
    names = {"np": np}
    exec(compile(tour_blocks(page), str(page), "exec"), names)
    return names


def test_readme_tour_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    names = run_page(README)
    surface = names["s"]
    assert math.isclose(surface.integrate(surface.gauss_curvature), 4 * math.pi, rel_tol=1e-3)  # Gauss–Bonnet
    assert np.isfinite(names["x"]).all() and not np.allclose(names["x"], names["sphere"].vertices)  # the cap deforms
    concentration = names["wave"].concentration()
    assert np.isfinite(concentration).all() and not np.array_equal(concentration, names["c0"])


def test_guide_examples_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    names = run_page(GUIDE)
    surface = names["s"]
    assert math.isclose(surface.integrate(surface.gauss_curvature), 4 * math.pi, rel_tol=1e-3)  # Gauss–Bonnet, to quadrature error
    assert (tmp_path / "finer.ply").exists()
    stepped, pulse = names["state"].c.numpy(), names["c0"]
    assert np.isfinite(stepped).all() and not np.array_equal(stepped, pulse)
    assert names["batch"].worlds == 3 and names["result"]["status"] == "done"
