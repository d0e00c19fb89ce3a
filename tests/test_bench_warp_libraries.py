"""`python benchmarks/warp_libraries.py --quick`: Warp's libraries against ours. Answers known in advance:
every colouring is a distance-two colouring of the Newton pattern, both CG solutions solve the system
SciPy solves directly to the tolerance, and bsr_mv and our kernel give SciPy's K @ x."""

import json

import numpy as np
import pytest
import scipy.sparse.linalg as sla

from wavewarp.benchmarks import warp_libraries as bench
from wavewarp.geometry import SurfaceTables
from wavewarp.mesh import icosphere


@pytest.fixture(scope="module")
def pattern():
    return bench.colouring_pattern(3)[0]


def test_distance_two_edges_are_the_pairs_sharing_a_row():
    pattern = bench.colouring_pattern(2)[0]
    expected = set()
    for i in range(pattern.shape[0]):
        row = pattern.indices[pattern.indptr[i] : pattern.indptr[i + 1]]
        expected |= {(a, b) for a in row for b in row if a < b}
    edges = bench.distance_two_edges(pattern)
    assert edges.dtype == np.int32 and edges.shape[1] == 2
    assert set(map(tuple, edges.tolist())) == expected and len(edges) == len(expected)


@pytest.mark.parametrize("method", bench.COLOURINGS)
def test_colourings_are_distance_two_colourings(pattern, method):
    colours, extra = bench.colour(pattern, method)
    n = pattern.shape[0]
    assert colours.shape == (n,) and colours.min() >= 0
    for i in range(n):  # no row of the pattern holds two vertices of one colour
        row = colours[pattern.indices[pattern.indptr[i] : pattern.indptr[i + 1]]]
        assert len(np.unique(row)) == len(row), (method, i)
    # the same from the patches themselves: the vertices of one patch carry distinct colours
    host = SurfaceTables.of(icosphere(1.0, 3), "3", device="cpu", dtype="float64").host
    for t in range(len(host.patch_start) - 1):
        patch = host.patch_vertices[host.patch_start[t] : host.patch_start[t + 1]]
        assert len(np.unique(colours[patch])) == len(patch), (method, t)
    assert colours.max() + 1 >= np.diff(pattern.indptr).max()  # a row's vertices need distinct colours
    if method != "ours":
        assert extra["reported_colours"] == colours.max() + 1
    assert bench.is_distance_two_colouring(pattern, colours)


def test_the_validity_check_rejects_a_colouring_with_a_clash(pattern):
    colours = bench.colour(pattern, "ours")[0]
    i = pattern.indices[pattern.indptr[0] : pattern.indptr[1]]
    clash = colours.copy()
    clash[i[1]] = clash[i[0]]  # two vertices of row 0 share a colour
    assert not bench.is_distance_two_colouring(pattern, clash)
    assert not bench.is_distance_two_colouring(pattern, np.zeros_like(colours))


@pytest.mark.parametrize("dtype", bench.DTYPES)
def test_cg_solutions_match_scipy_to_the_tolerance(dtype):
    case = bench.CGCase(3, dtype, "cpu")
    A = case.matrix.toarray()
    b = case.b_host.astype(np.float64)
    exact = sla.spsolve(case.matrix.tocsc(), b)
    assert np.linalg.norm(A @ exact - b) <= 1e-13 * np.linalg.norm(b)
    condition = np.linalg.cond(A)  # relative error <= condition × relative residual
    solutions = {}
    for name in bench.CG_SOLVERS:
        case.solve(name)
        x = solutions[name] = case.solution(name)
        residual = np.linalg.norm(b - A @ x) / np.linalg.norm(b)
        # ours stops on the Jacobi-weighted residual, Warp's on ‖r‖₂: equal up to the norms' equivalence factor
        bound = case.tol * np.sqrt(np.max(np.diag(A)) / np.min(np.diag(A)))
        assert residual <= 1.5 * bound, (name, residual, bound)
        assert np.linalg.norm(x - exact) / np.linalg.norm(exact) <= 1.5 * condition * bound, name
        assert case.iterations(name) > 0
    for name in bench.CG_SOLVERS[1:]:
        assert np.linalg.norm(solutions[name] - solutions["ours"]) <= 3 * condition * case.tol * np.linalg.norm(exact)


@pytest.mark.parametrize("dtype", bench.DTYPES)
def test_bsr_mv_and_ours_equal_scipy_k_times_x(dtype):
    case = bench.SpmvCase(3, dtype, "cpu")
    assert case.bsr.nnz == case.K.nnz and case.bsr.shape == case.K.shape
    host_K = case.op.stiffness_matrix()  # assembled on the host from the same geometry, float64
    eps = np.finfo(dtype).eps
    for kind, x in case.inputs.items():
        reference = case.K @ x.astype(np.float64)
        for name in bench.SPMV_METHODS:
            y = case.result(name, x)
            # every entry a sum of ~20 dtype products: within 40 eps of the largest term
            scale = np.abs(case.K) @ np.abs(x.astype(np.float64))
            assert np.all(np.abs(y - reference) <= 40 * eps * scale + 1e-300), (kind, name)
            if dtype == "float64":
                assert np.allclose(y, host_K @ x, rtol=0, atol=1e-12 * np.abs(reference).max()), (kind, name)


@pytest.mark.slow  # a benchmark's smoke run
def test_quick_run_writes_a_row_per_configuration(tmp_path):
    assert bench.main(["--quick", "--device", "cpu", "--out", str(tmp_path), "--repeats", "1"]) == 0
    result = json.loads((tmp_path / "warp_libraries.json").read_text())
    assert (tmp_path / "warp_libraries.png").stat().st_size > 0
    assert result["benchmark"] == "warp_libraries" and result["device"] == "cpu" and result["quick"] and result["date"]
    rows = result["rows"]
    assert {(r["level"], r["method"]) for r in rows if r["item"] == "colouring"} == {
        (level, method) for level in (3, 4) for method in bench.COLOURINGS
    }
    assert all(r["valid"] for r in rows if r["item"] == "colouring")
    for item, methods in (("cg", bench.CG_SOLVERS), ("spmv", bench.SPMV_METHODS)):
        keys = {(r["level"], r["dtype"], r["method"]) for r in rows if r["item"] == item}
        assert keys == {(level, dtype, m) for level in (3, 4) for dtype in bench.DTYPES for m in methods}, item
    for r in rows:
        if r["item"] == "cg":
            assert r["ms"] > 0 and r["iterations"] > 0 and r["residual"] <= 2 * r["tol"] * r["norm_equivalence"]
        if r["item"] == "spmv":
            assert r["us"] > 0 and r["difference_vs_ours"] < 100 * np.finfo(r["dtype"]).eps
    for entry in result["ratios"]:  # ours / Warp's, from this run's rows
        ours = next(r for r in rows if r["item"] == entry["item"] and r["level"] == entry["level"]
                    and r.get("dtype") == entry["dtype"] and r["method"] == "ours")  # fmt: skip
        warp = next(r for r in rows if r["item"] == entry["item"] and r["level"] == entry["level"]
                    and r.get("dtype") == entry["dtype"] and r["method"] == entry["warp"])  # fmt: skip
        key = {"colouring": "seconds", "cg": "ms", "spmv": "us"}[entry["item"]]
        assert entry["ours_over_warp"] == pytest.approx(ours[key] / warp[key], rel=1e-12)
