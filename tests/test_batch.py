"""Batched worlds (wavewarp/batch.py, issue 28): many shells of one topology in one model, stepped
together. The reference for each world is its own single run, computed here: in deterministic
float64 the two must agree bit for bit (every reduction is per world and gathered in a fixed order)."""

from dataclasses import replace

import numpy as np
import pytest
import warp as wp

from wavewarp.batch import check_batch
from wavewarp.device import set_deterministic
from wavewarp.driver import simulate
from wavewarp.geometry import patch_tables
from wavewarp.mesh import Mesh, icosphere
from wavewarp.parameters import load_scene, resolve
from wavewarp.relax import RelaxationError
from wavewarp.runs import imperfect
from wavewarp.scenes import sphere_walker as scene
from wavewarp.self_contact import SelfContact
from wavewarp.shell import Shell
from wavewarp.walker import WalkerRun, sphere_walker_recipe


@pytest.fixture
def deterministic():
    set_deterministic(True)
    yield
    set_deterministic(False)


def noisy_spheres(count, level=1, amplitude=0.02):
    sphere = icosphere(1.0, level)
    return [imperfect(sphere, amplitude, seed) for seed in range(count)]


def test_union_holds_the_worlds_as_contiguous_blocks_and_its_patch_tables_tile():
    meshes = noisy_spheres(3)
    union = Mesh.union(meshes)
    n, t = meshes[0].n_vertices, meshes[0].n_triangles
    assert (union.worlds, union.vertices_per_world, union.triangles_per_world) == (3, n, t)
    for w, mesh in enumerate(meshes):
        np.testing.assert_array_equal(union.world(w).vertices, mesh.vertices)
        np.testing.assert_array_equal(union.world(w).triangles, mesh.triangles)
    one, all_ = patch_tables(meshes[0]), patch_tables(union)
    size = len(one.patch_vertices)
    np.testing.assert_array_equal(all_.patch_vertices, np.concatenate([one.patch_vertices + w * n for w in range(3)]))
    starts = np.concatenate([one.patch_start[:-1] + w * size for w in range(3)])
    np.testing.assert_array_equal(all_.patch_start[:-1], starts)


def test_union_refuses_meshes_of_another_topology():
    with pytest.raises(ValueError, match="world 1's triangles differ"):
        Mesh.union([icosphere(1.0, 1), icosphere(1.0, 2)])


@pytest.mark.parametrize("deterministic_mode", [True, False])
def test_each_world_of_a_batched_shell_has_its_own_shells_forces_energy_and_volume(deterministic_mode):
    """Per-world h, Y, AC, AI, μV: forces and volumes of the batch equal those of each world's own shell
    (bitwise in deterministic mode), the energy their sum."""
    set_deterministic(deterministic_mode)
    try:
        meshes = noisy_spheres(3)
        thickness, young, mu = [0.1, 0.15, 0.1], [1.0, 1.0, 2.0], [2.0, 0.0, 5.0]
        AC, AI = [0.3, -0.2, 0.0], [0.0, 0.5, 1.0]
        rng = np.random.default_rng(3)
        c = [rng.uniform(0, 1, m.n_vertices) for m in meshes]
        x = [m.vertices * 1.05 + 0.01 * rng.standard_normal(m.vertices.shape) for m in meshes]
        batch = Shell(Mesh.union(meshes), thickness, young, AC=AC, AI=AI, volume_penalty=mu, dtype="float64",
                      device="cpu")  # fmt: skip
        forces = batch.forces(np.concatenate(x), np.concatenate(c))
        energy = batch.energy(np.concatenate(x), np.concatenate(c))
        volumes = batch.volume(np.concatenate(x))
        n = meshes[0].n_vertices
        total = 0.0
        for w, mesh in enumerate(meshes):
            single = Shell(mesh, thickness[w], young[w], AC=AC[w], AI=AI[w], volume_penalty=mu[w], dtype="float64",
                           device="cpu")  # fmt: skip
            expected = single.forces(x[w], c[w])
            if deterministic_mode:
                np.testing.assert_array_equal(forces[w * n:(w + 1) * n], expected)
            else:
                np.testing.assert_allclose(forces[w * n:(w + 1) * n], expected, rtol=1e-12,
                                           atol=1e-12 * np.abs(expected).max())  # fmt: skip
            assert volumes[w] == pytest.approx(single.volume(x[w]), rel=1e-13)
            total += single.energy(x[w], c[w])
        assert energy == pytest.approx(total, rel=1e-12)
    finally:
        set_deterministic(False)


def quick_worlds():
    base = resolve(scene.Parameters, {"level": 1, "periods": 0.1, "frames": 2, "settle": 1.0, "dtype": "float64",
                                      "noise": 0.01, "contact_sweeps": 2})  # fmt: skip
    return [replace(base, AC=0.1), replace(base, AC=0.2, mirror=True, mu_v=0.0, young=250.0, thickness=2.5, elongation=1.15)]


OVERDAMPED_BODY = {"mechanics": "overdamped", "contact_solve": "implicit", "drag_frame": "body"}


@pytest.mark.parametrize("mechanics", [{"mechanics": "overdamped"},
                                       pytest.param({"mechanics": "inertial"}, marks=pytest.mark.slow),
                                       pytest.param(OVERDAMPED_BODY, marks=pytest.mark.slow)])  # fmt: skip
def test_each_world_of_a_walker_batch_equals_its_single_run_bit_for_bit(deterministic, device, mechanics):
    """Two sphere walkers differing in AC, Y, h, μV, the rest shape's elongation, the wave's side and the noise
    seed: the batch's
    positions, concentrations, trace and measurements of each world are those of its own WalkerRun
    (which settles with the batch's mechanics steps: the worlds share the strictest). With the drag in
    the body frame each world solves its own body velocity."""
    ps, seeds = [replace(p, **mechanics) for p in quick_worlds()], [0, 1]  # the worlds share the drag, ζ = 60
    batch = scene.build_batch(ps, seeds=seeds, device=device, report=lambda message: None)
    results = batch.run()
    x, c, n = batch.dynamics.positions(), batch.wave.concentration(), batch.vertices
    for w, (p, seed) in enumerate(zip(ps, seeds)):
        mesh, options = sphere_walker_recipe(p, device=device)
        run = WalkerRun(scene.NAME, imperfect(mesh, p.noise * p.radius, seed), p, device=device,
                        mechanics_dt=batch.settle_dt, report=lambda message: None, **options)  # fmt: skip
        outcome = simulate(run, [])
        assert run.coupled.substeps == batch.coupled.substeps and outcome.failure is None
        np.testing.assert_array_equal(x[w * n:(w + 1) * n], run.dynamics.positions())
        np.testing.assert_array_equal(c[w * n:(w + 1) * n], run.wave.concentration())
        np.testing.assert_array_equal(np.unique(batch.traces[w], axis=0), np.unique(run.trace, axis=0))
        assert results[w]["status"] == "done" and results[w]["frames"] == run.frames + 1
        assert results[w]["measurements"] == outcome.measurements
    assert len({tuple(batch.traces[w][-1, 2:5]) for w in range(2)}) == 2  # the worlds did differ


def test_a_world_that_blows_up_stops_alone(deterministic, device):
    """A NaN put into one world's velocities after the first frame stops that world at the chunk's start
    (its state finite, frozen) and reports it; the other worlds end as in a batch without the NaN (the
    inertial mechanics, whose velocities are state: the overdamped ones follow from the forces)."""
    ps, seeds = [replace(p, mechanics="inertial") for p in quick_worlds()], [0, 1]
    clean = scene.build_batch(ps, seeds=seeds, device=device, report=lambda message: None)
    clean.run()
    batch = scene.build_batch(ps, seeds=seeds, device=device, report=lambda message: None)
    n = batch.vertices
    frozen = {}

    def poison(frames):
        if frames == 1:
            v = batch.dynamics.velocities()
            frozen.update(x=batch.dynamics.positions()[n:], c=batch.wave.concentration()[n:])
            v[n + 5] = np.nan
            batch.dynamics.state.set("v", v)

    results = batch.run(progress=poison)
    assert results[0]["status"] == "done" and results[0]["frames"] == batch.frames + 1
    assert results[1]["status"] == "stopped" and "blew up" in results[1]["stopped"] and results[1]["frames"] == 2
    np.testing.assert_array_equal(batch.dynamics.positions()[:n], clean.dynamics.positions()[:n])
    np.testing.assert_array_equal(batch.wave.concentration()[:n], clean.wave.concentration()[:n])
    np.testing.assert_array_equal(batch.dynamics.positions()[n:], frozen["x"])
    np.testing.assert_array_equal(batch.wave.concentration()[n:], frozen["c"])
    first_frame_end = batch.steps_per_frame * batch.wave.dt  # its trace ends where it stopped
    assert np.all(np.isfinite(batch.traces[1])) and batch.traces[1][-1, 0] <= first_frame_end + 1e-9


def test_a_batch_refuses_worlds_that_differ_in_a_shared_parameter():
    ps = quick_worlds()
    with pytest.raises(ValueError, match="world 1 differs from world 0 in gamma") as walker:
        scene.build_batch([ps[0], replace(ps[0], gamma=0.3)], seeds=[0, 0], device="cpu")
    assert "mu_v, noise, elongation, mirror (and the seed)" in str(walker.value)
    quasi_static = resolve(load_scene("buckling-modes").Parameters, None, [])
    with pytest.raises(ValueError, match="but young, tau_m, thickness, AC, AI, mu_v, noise \\(and the seed\\)"):
        check_batch([quasi_static, replace(quasi_static, gamma=0.3)])  # names only the scene's own


def test_batched_shell_parameters_take_one_value_or_one_per_world():
    union = Mesh.union(noisy_spheres(2))
    with pytest.raises(ValueError, match="AC must be one number or a list of 2"):
        Shell(union, 0.1, 1.0, AC=[0.1, 0.2, 0.3], device="cpu")
    shell = Shell(union, [0.1, 0.2], 1.0, AC=0.3, device="cpu")
    assert shell.AC == 0.3 and list(shell.thickness) == [0.1, 0.2]
    assert wp.types.types_equal(shell.reference.couplings[0].dtype, wp.float32)


def test_each_world_of_a_batched_relaxation_equals_its_own_relaxation_bit_for_bit():
    """Nonlinear CG with one line search and one convergence test per world: three noisy spheres with
    per-world h, AC, AI, μV under per-world concentrations relax to their own shells' equilibria, the
    same iterations and energies, bit for bit (float64, CPU: every sum in a fixed order)."""
    meshes = noisy_spheres(3)
    thickness, AC, AI, mu = [0.05, 0.08, 0.05], [0.3, 0.0, 0.2], [0.0, 0.4, 0.2], [5.0, 0.0, 10.0]
    c = [np.full(m.n_vertices, value) for m, value in zip(meshes, (0.5, 0.8, 0.3))]
    batch = Shell(Mesh.union(meshes), thickness, 1.0, AC=AC, AI=AI, volume_penalty=mu, dtype="float64", device="cpu")
    x = batch.relax(batch.mesh.vertices, np.concatenate(c), method="ncg")
    histories = batch.relax_history
    n = meshes[0].n_vertices
    for w, mesh in enumerate(meshes):
        single = Shell(mesh, thickness[w], 1.0, AC=AC[w], AI=AI[w], volume_penalty=mu[w], dtype="float64", device="cpu")
        np.testing.assert_array_equal(x[w * n:(w + 1) * n], single.relax(mesh.vertices, c[w], method="ncg"))
        assert histories[w] == single.relax_history and len(histories[w]) > 10


def test_a_batched_relaxation_names_the_worlds_that_did_not_converge():
    """A budget too small for the contracting world: the error names it; the world at rest converged."""
    meshes = noisy_spheres(2)
    batch = Shell(Mesh.union(meshes), 0.05, 1.0, AC=[0.0, 0.5], dtype="float64", device="cpu")
    with pytest.raises(RelaxationError, match=r"in world 1 \(the others converged\)") as stopped:
        batch.relax(batch.mesh.vertices, 1.0, max_iterations=5)
    assert stopped.value.worlds == [1]
    n = meshes[0].n_vertices
    np.testing.assert_array_equal(stopped.value.x[:n], meshes[0].vertices)  # at rest under AC = 0: no step taken
    with pytest.raises(ValueError, match="batched worlds relax by nonlinear CG"):
        batch.relax(batch.mesh.vertices, method="newton")


def test_self_contact_refuses_batched_worlds():
    shell = Shell(Mesh.union(noisy_spheres(2)), 0.1, 1.0, device="cpu", dtype="float64")
    with pytest.raises(ValueError, match="would touch each other"):
        SelfContact(shell)
