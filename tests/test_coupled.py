"""Quasi-static coupling: a uniform concentration drives the sphere to the closed-form radius (docs/theory/scenes.md)."""

import math

import numpy as np
import pytest

from wavewarp.coupled import QuasiStatic
from wavewarp.geometry import limit_positions
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.relax import RelaxationError
from wavewarp.shell import Shell
from wavewarp.waves import Telegraph

F64 = dict(device="cpu", dtype="float64")


def closed_form_stretch(AC, AI, c, h_over_R):
    """Real root near 1 of λ³ - (s - ε) λ - ε k = 0 (no volume term), s = e^{-AC c}, k = 1 - AI c, ε = h²/(6R²)."""
    s, k, eps = math.exp(-AC * c), 1 - AI * c, h_over_R**2 / 6
    roots = np.roots([1.0, 0.0, -(s - eps), -eps * k])
    real = roots[np.abs(roots.imag) < 1e-12].real
    return float(real[np.argmin(np.abs(real - 1))])


@pytest.mark.parametrize("sensitive", [True, False])
def test_uniform_concentration_reaches_the_closed_form_radius_and_moves_the_wave(sensitive, device):
    R, h, AC, AI, c = 1.0, 0.05, 0.3, 0.5, 1.0
    mesh = icosphere(R, 3)
    on_device = dict(device=device, dtype="float64")
    shell = Shell(mesh, thickness=h, young=1.0, AC=AC, AI=AI, **on_device)
    op = LaplaceBeltrami(mesh, **on_device)
    wave = Telegraph(op, 1.0, c0=np.full(mesh.n_vertices, c))  # K·1 = 0: c stays uniform
    bound = wave.stable_dt
    run = QuasiStatic(shell, wave, sensitive=sensitive, chemistry_steps=5)
    run.step()
    np.testing.assert_allclose(wave.concentration(), c, atol=1e-12)
    stretch = closed_form_stretch(AC, AI, c, h / R)
    radius = np.linalg.norm(limit_positions(mesh, run.positions(), **F64), axis=1).mean()
    assert abs(radius / R - stretch) <= 1e-3 * abs(1 - stretch)
    if sensitive:  # the wave now runs on the shrunken sphere: area λ² and a bound λ times smaller
        assert op.area == pytest.approx(4 * math.pi * (stretch * R) ** 2, rel=1e-4)
        assert wave.stable_dt == pytest.approx(stretch * bound, rel=1e-3)
    else:
        assert op.area == pytest.approx(4 * math.pi * R**2, rel=1e-4)
        assert wave.stable_dt == bound


def test_mismatched_parts_are_refused():
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, thickness=0.05, young=1.0, **F64)
    wave32 = Telegraph(LaplaceBeltrami(mesh, device="cpu", dtype="float32"), 1.0, c0=np.zeros(mesh.n_vertices))
    with pytest.raises(ValueError, match="must share device and dtype"):
        QuasiStatic(shell, wave32)
    other = Telegraph(LaplaceBeltrami(icosphere(1.0, 1), **F64), 1.0, c0=np.zeros(42))
    with pytest.raises(ValueError, match="must share one mesh"):
        QuasiStatic(shell, other)
    with pytest.raises(ValueError, match="wave must be"):
        QuasiStatic(shell, "telegraph")


def test_accept_unconverged_takes_a_spent_budget_and_the_default_refuses_it():
    mesh = icosphere(1.0, 2)
    c0 = np.full(mesh.n_vertices, 1.0)
    parts = dict(thickness=0.05, young=1.0, AC=0.3, AI=0.5, **F64)
    with pytest.raises(RelaxationError, match="relax stopped after 3 iterations"):
        QuasiStatic(Shell(mesh, **parts), Telegraph(LaplaceBeltrami(mesh, **F64), 1.0, c0=c0), max_iterations=3,
                    method="ncg")  # fmt: skip
    run = QuasiStatic(Shell(mesh, **parts), Telegraph(LaplaceBeltrami(mesh, **F64), 1.0, c0=c0), max_iterations=3,
                      accept_unconverged=True, method="ncg")  # fmt: skip
    assert run.unconverged == 1 and run.relax_iterations == [3]
    energy = run.shell.energy(run.positions(), c0)
    assert energy < run.shell.energy(mesh.vertices, c0)  # three iterations of progress, kept
    for _ in range(3):
        run.step()  # each step continues the relaxation from where the last one stopped
    assert run.shell.energy(run.positions(), c0) < energy


def test_accept_unconverged_takes_a_round_off_stop_and_the_default_refuses_it(monkeypatch):
    """A relaxation whose line search finds no lower energy far above tol (as at the buckling's
    sharpest fold, docs/theory/scenes.md): the default stops, accept_unconverged goes on from where it
    stopped and count it."""
    import wavewarp.coupled

    mesh = icosphere(1.0, 2)
    c0 = np.full(mesh.n_vertices, 1.0)
    stopped_at = mesh.vertices * 0.99

    def no_lower_energy(shell, x, tol, max_iterations, out=None, **method):
        shell.relax_history = [0.0, -1.0]
        raise RelaxationError("relax stopped after 1 iterations (the line search found no lower energy)", 0.5,
                              stopped_at, round_off=True)  # fmt: skip

    monkeypatch.setattr(wavewarp.coupled, "relax", no_lower_energy)

    def coupled(**options):
        return QuasiStatic(Shell(mesh, thickness=0.05, young=1.0, AI=0.5, **F64),
                           Telegraph(LaplaceBeltrami(mesh, **F64), 1.0, c0=c0), **options)  # fmt: skip

    with pytest.raises(RelaxationError, match="no lower energy"):
        coupled()
    run = coupled(accept_unconverged=True)
    assert run.unconverged == 1 and np.array_equal(run.positions(), stopped_at)
