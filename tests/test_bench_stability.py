"""The stability benchmark (issue 7, docs/theory/scenes.md): its quick run through the CLI, and its
measured largest stable steps against bounds computed here, independently of the steppers'
power iteration and Lanczos (dense eigenvalues of M⁻¹K, W_2 K and of a finite-difference Hessian)."""

import json
import math

import numpy as np
import pytest
import scipy.linalg

from wavewarp.benchmarks import stability
from wavewarp.cli import main as cli
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.shell import Shell

RESOLUTION = 0.005  # bisection width, relative to the predicted bound
NU = -0.01  # docs/theory/chemistry.md, the benchmark's FHN


@pytest.mark.slow
def test_quick_benchmark_writes_its_table_and_chart(tmp_path):
    assert cli(["bench", "stability", "--quick", "--device", "cpu", "--out", str(tmp_path)]) == 0
    with open(tmp_path / "stability_cpu_quick.json") as f:
        result = json.load(f)
    assert (tmp_path / "stability_cpu_quick.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert result["benchmark"] == "stability" and result["device"] == "cpu" and result["quick"]
    assert "no stability bound" in result["relax_note"]
    methods = {row["method"] for row in result["rows"]}
    assert methods == {"telegraph", "fhn-explicit", "fhn-imex", "dynamics"}
    assert {(r["discretization"], r["mass_corrections"]) for r in result["rows"] if r["method"] == "telegraph"} == {
        ("subdivision", 0), ("subdivision", 2), ("p1", 0)}  # fmt: skip
    assert len({r["thickness"] for r in result["rows"] if r["method"] == "dynamics"}) >= 2
    for row in result["rows"]:
        for key in ("level", "vertices", "dtype", "predicted_dt", "measured_dt", "first_unstable_dt", "ratio", "steps"):
            assert key in row, (row["method"], key)
        assert not row["bracket_missed"]
        width = row["first_unstable_dt"] - row["measured_dt"]
        assert 0 < width <= 1.001 * result["resolution"] * row["predicted_dt"]
        expected = row.get("expected_ratio", 1.0)  # FHN at rest: the bound's L_f is conservative there
        assert row["ratio"] == pytest.approx(expected, abs=1.5 * result["resolution"]), row
    imex = [r for r in result["rows"] if r["method"] == "fhn-imex"]
    assert imex and all(r["over_explicit_bound"] > 10 for r in imex)  # no diffusive limit
    assert result["relax"] and all(r["converged"] and r["energy_monotone"] for r in result["relax"])


def contains(row, bound, tolerance):
    """The measured bracket [largest stable, first unstable] holds `bound` (within `tolerance`, relative)."""
    return row["measured_dt"] <= bound * (1 + tolerance) and row["first_unstable_dt"] >= bound * (1 - tolerance)


def dense_largest_eigenvalue(level, discretization="subdivision", corrections=0):
    """λ_max(W_p K), W_0 = M⁻¹ (lumped): dense, float64."""
    op = LaplaceBeltrami(icosphere(1.0, level), discretization=discretization, device="cpu", dtype="float64")
    K, m = op.stiffness_matrix().toarray(), op.mass()
    if corrections == 0:
        return scipy.linalg.eigh(K, np.diag(m), eigvals_only=True)[-1]
    G = np.diag(1 / m)
    W, term = G.copy(), G.copy()
    for _ in range(corrections):
        term = term - G @ (op.mass_matrix() @ term)
        W += term
    return np.max(np.linalg.eigvals(W @ K).real)


@pytest.mark.parametrize("discretization, corrections", [("subdivision", 0), ("subdivision", 2), ("p1", 0)])
def test_telegraph_limit_is_two_over_gamma_root_lambda(discretization, corrections):
    row = stability.telegraph_row(2, discretization, corrections, "float64", "cpu", RESOLUTION)
    bound = 2 / (stability.GAMMA * math.sqrt(dense_largest_eigenvalue(2, discretization, corrections)))
    assert contains(row, bound, 1e-3), (row["measured_dt"], bound, row["first_unstable_dt"])


def test_fhn_explicit_limit_follows_the_reaction_slope_of_the_state():
    """Euler on the top mode: unstable past 2 / (γ² λ_max - f'(c)), f = c(1-c)(c-ν): at rest
    f'(0) = -ν (the bound's L_f = 1 - ν is conservative there), excited f'(1) = ν - 1 (sharp)."""
    diffusion = stability.GAMMA**2 * dense_largest_eigenvalue(2)
    rest = stability.fhn_row(2, "rest", "explicit", "float64", "cpu", RESOLUTION)
    excited = stability.fhn_row(2, "excited", "explicit", "float64", "cpu", RESOLUTION)
    assert contains(rest, 2 / (diffusion + NU), 3e-3), rest
    assert contains(excited, 2 / (diffusion + 1 - NU), 3e-3), excited
    assert rest["measured_dt"] > 1.04 * excited["first_unstable_dt"]  # 17.4 + 1.01 against 17.4 - 0.01


def test_fhn_imex_limit_is_the_reaction_alone():
    """IMEX at c = 1: the uniform mode (K·1 = 0) steps by 1 + dt f'(1): unstable past 2 / (1 - ν)."""
    row = stability.fhn_row(2, "excited", "imex", "float64", "cpu", RESOLUTION)
    assert contains(row, 2 / (1 - NU), 3e-3), row
    assert row["over_explicit_bound"] > 15  # level 2, γ = 1: the explicit bound is 2 / 18.4


def test_shell_dynamics_limit_is_two_over_omega():
    """Symplectic Euler: unstable past 2/ω, ω² the largest eigenvalue of M⁻¹H with H a dense
    central-difference Hessian of the shell's forces and M = ρ × the lumped mass."""
    thickness = 0.084
    mesh = icosphere(1.0, 1)
    shell = Shell(mesh, thickness, stability.YOUNG, device="cpu", dtype="float64")
    n, step = mesh.n_vertices, 1e-6
    H = np.empty((3 * n, 3 * n))
    for j in range(3 * n):
        dx = np.zeros((n, 3))
        dx.flat[j] = step
        H[:, j] = (shell.forces(mesh.vertices - dx) - shell.forces(mesh.vertices + dx)).ravel() / (2 * step)
    mass = np.repeat(thickness * LaplaceBeltrami(mesh, device="cpu", dtype="float64").mass(), 3)
    omega = math.sqrt(scipy.linalg.eigh(0.5 * (H + H.T), np.diag(mass), eigvals_only=True)[-1])
    row = stability.dynamics_row(1, thickness, 1e-6, "float64", "cpu", RESOLUTION)
    assert contains(row, 2 / omega, 1e-3), (row["measured_dt"], 2 / omega, row["first_unstable_dt"])
