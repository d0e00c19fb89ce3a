"""Warp's own libraries against our hand-written code, side by side in one run: graph colouring,
conjugate gradients for (M + s K) x = b, and the sparse product K x.

    python benchmarks/warp_libraries.py --device cpu --out benchmarks/results [--quick]

1. Colouring (host; Warp's colouring takes CPU arrays only, ours is NumPy): the distance-two
   colouring of the Newton Hessian's pattern P (`newton.patch_pairs`, vertices sharing a triangle
   patch), by the greedy NumPy colouring wavewarp used before ("ours", in vertex order) and by
   `warp.utils.graph_coloring_assign` (MCS and GREEDY, each also followed by
   `graph_coloring_balance` to a max/min group ratio of 1.1) on the graph whose edges are the
   off-diagonal nonzeros of P P. Warp's time includes building that edge list (ours builds P P
   too); the pattern itself is common and timed apart. Every colouring is checked independently:
   no row of P may hold two vertices of one colour. Colours count: each costs 6 force evaluations.
2. CG for (M + s K) x = b (M lumped mass, K the assembled stiffness, s = dt γ² = 0.5 · 0.2²,
   b = M (c0 + dt f(c0)) from a Gaussian pulse c0, x0 = c0, as one IMEX FitzHugh–Nagumo step):
   ours (`ShiftedMassSolver`) against `warp.optim.linear.cg` with a Jacobi preconditioner on a
   `BsrMatrix` of M + s K (1×1 blocks) and on a `LinearOperator` wrapping our K action. Same tol
   (float32 1e-5, float64 1e-10, FitzHughNagumo's defaults), same b and x0. The stopping rules
   differ in the norm only: ours r·P r ≤ tol² b·P b (P = 1 / diag(M + s K)), Warp's
   ‖r‖₂ ≤ max(tol ‖b‖₂, atol); we pass atol=0 (Warp's default atol=tol is absolute and would stop
   early on small b) and check_every=1 on the CPU (0 on CUDA: device-side exit; with 0 on the CPU
   Warp runs all maxiter iterations). Both use the recursive residual; the true residuals of the
   results, in both norms, are recorded, with the iterations and the error against SciPy's direct
   solve of the same (dtype-rounded) matrix in float64.
3. K x: our gather kernel (`assembled_stiffness_kernel`, Σ_J K_IJ (x_J − x_I)) against
   `warp.sparse.bsr_mv` on a BsrMatrix of the same K (1×1 blocks, the diagonal −Σ_J K_IJ added),
   compared with SciPy's K @ x in float64 for a random and a smooth x.

Timings synchronise the device and are medians of repeats after a warm-up; on CUDA the CG solves
and the products are timed as captured graphs (as the steppers run them). Writes
warp_libraries.json (device, date, rows) and warp_libraries.png to --out.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from datetime import date
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import warp as wp

DTYPES = ("float32", "float64")
CG_TOL = {"float32": 1e-5, "float64": 1e-10}  # FitzHughNagumo's defaults
DT, GAMMA, NU = 0.5, 0.2, -0.01  # one IMEX step: s = dt γ²
BALANCE_RATIO = 1.1
COLOURINGS = ("ours", "warp MCS", "warp GREEDY", "warp MCS + balance", "warp GREEDY + balance", "warp best of MCS, GREEDY")
CG_SOLVERS = ("ours", "warp cg, BsrMatrix", "warp cg, our K")
SPMV_METHODS = ("ours", "warp bsr_mv")
GRAPH_PRODUCTS = 100  # K x products per captured graph (CUDA)


@wp.kernel
def shifted_matvec_kernel(x: wp.array(dtype=Any), Kx: wp.array(dtype=Any), mass: wp.array(dtype=Any), shift: Any,
                          alpha: Any, beta: Any, y: wp.array(dtype=Any), z: wp.array(dtype=Any)):  # fmt: skip
    """z = alpha (M + shift K) x + beta y, with Kx = K x given (y is not read when beta = 0)."""
    i = wp.tid()
    v = alpha * (mass[i] * x[i] + shift * Kx[i])
    if beta != type(beta)(0.0):
        v += beta * y[i]
    z[i] = v


def sync_timed(device, function) -> float:
    """Wall seconds of function() with the device synchronised before and after."""
    wp.synchronize_device(device)
    start = time.perf_counter()
    function()
    wp.synchronize_device(device)
    return time.perf_counter() - start


# ---------------------------------------------------------------------------------------- colouring
def colouring_pattern(level: int):
    """(P, seconds): the Newton Hessian's pattern on the level-L icosphere (as NewtonFinish builds it)."""
    from wavewarp.geometry import SurfaceTables
    from wavewarp.mesh import icosphere
    from wavewarp.newton import patch_pairs

    mesh = icosphere(1.0, level)
    host = SurfaceTables.of(mesh, "3", device="cpu", dtype="float64").host
    start = time.perf_counter()
    pattern = patch_pairs(host, mesh.n_vertices)
    return pattern, time.perf_counter() - start


def distance_two_edges(pattern: sp.csr_matrix) -> np.ndarray:
    """(E, 2) int32: the pairs i < j that share a row of `pattern` (off-diagonal nonzeros of P P)."""
    square = (pattern @ pattern).tocoo()
    upper = square.row < square.col
    return np.ascontiguousarray(np.stack([square.row[upper], square.col[upper]], axis=1), dtype=np.int32)


def greedy_distance_two_colouring(pattern: sp.csr_matrix) -> np.ndarray:
    """Greedy colours such that no row of `pattern` holds two vertices of one colour: the NumPy colouring
    wavewarp used before Warp's (the baseline of this comparison)."""
    square = (pattern @ pattern).tocsr()
    colour = np.full(pattern.shape[0], -1, dtype=np.int32)
    for i in range(pattern.shape[0]):
        used = colour[square.indices[square.indptr[i] : square.indptr[i + 1]]]
        free = np.ones(len(used) + 1, dtype=bool)
        free[used[(used >= 0) & (used <= len(used))]] = False
        colour[i] = int(np.argmax(free))
    return colour


def is_distance_two_colouring(pattern: sp.csr_matrix, colour: np.ndarray) -> bool:
    """True when every vertex has a colour >= 0 and no row of `pattern` holds two vertices of one colour."""
    colour = np.asarray(colour)
    if colour.shape != (pattern.shape[1],) or colour.min() < 0:
        return False
    rows = np.repeat(np.arange(pattern.shape[0], dtype=np.int64), np.diff(pattern.indptr))
    keys = rows * (int(colour.max()) + 1) + colour[pattern.indices]
    return len(np.unique(keys)) == len(keys)


def colour(pattern: sp.csr_matrix, method: str) -> tuple[np.ndarray, dict]:
    """One colouring of `pattern` by `method` (COLOURINGS): (colours, timings and extras)."""
    if method == "ours":
        start = time.perf_counter()
        colours = greedy_distance_two_colouring(pattern)
        return colours, {"seconds": time.perf_counter() - start}
    start = time.perf_counter()
    edges = wp.array(distance_two_edges(pattern), dtype=wp.int32, device="cpu")
    edges_seconds = time.perf_counter() - start
    algorithms = ("MCS", "GREEDY") if method.startswith("warp best") else (method.split()[1],)
    start = time.perf_counter()
    candidates = []
    for name in algorithms:  # "best of": both, keeping the one with fewer colours
        node_colours = wp.empty(pattern.shape[0], dtype=wp.int32, device="cpu")
        count = wp.utils.graph_coloring_assign(edges, node_colours, wp.utils.GraphColoringAlgorithm[name])
        candidates.append((count, node_colours))
    count, node_colours = min(candidates, key=lambda candidate: candidate[0])
    assign_seconds = time.perf_counter() - start
    extra = {"edges": int(edges.shape[0]), "edges_seconds": edges_seconds, "assign_seconds": assign_seconds,
             "reported_colours": int(count)}  # fmt: skip
    balance_seconds = 0.0
    if method.endswith("balance"):
        start = time.perf_counter()
        extra["balance_ratio_reported"] = float(wp.utils.graph_coloring_balance(edges, node_colours, count, BALANCE_RATIO))
        balance_seconds = time.perf_counter() - start
    extra["balance_seconds"] = balance_seconds
    extra["seconds"] = edges_seconds + assign_seconds + balance_seconds
    return node_colours.numpy().copy(), extra


def colouring_rows(level: int, repeats: int) -> list[dict]:
    pattern, pattern_seconds = colouring_pattern(level)
    lower_bound = int(np.diff(pattern.indptr).max())  # the vertices of one row need distinct colours
    rows = []
    for method in COLOURINGS:
        runs = [colour(pattern, method) for _ in range(repeats + 1)][1:]  # the first is a warm-up
        colours, extra = runs[-1]
        sizes = np.bincount(colours)
        row = {"item": "colouring", "level": level, "vertices": pattern.shape[0], "pattern_nnz": int(pattern.nnz),
               "method": method, "seconds": float(np.median([r[1]["seconds"] for r in runs])),
               "colours": int(colours.max()) + 1, "lower_bound": lower_bound,
               "valid": bool(is_distance_two_colouring(pattern, colours)),
               "deterministic": all(np.array_equal(r[0], colours) for r in runs),
               "max_min_group_ratio": float(sizes.max() / max(sizes.min(), 1)), "pattern_seconds": pattern_seconds}  # fmt: skip
        for key in ("edges", "edges_seconds", "assign_seconds", "balance_seconds", "reported_colours", "balance_ratio_reported"):
            if key in extra:
                row[key] = float(np.median([r[1][key] for r in runs])) if key.endswith("seconds") else extra[key]
        rows.append(row)
    return rows


# --------------------------------------------------------------------------------------- operators
def operator(level: int, dtype: str, device):
    from wavewarp.laplace import LaplaceBeltrami
    from wavewarp.mesh import icosphere

    return LaplaceBeltrami(icosphere(1.0, level), device=device, dtype=dtype)  # subdivision, assembled


def device_stiffness(op) -> sp.csr_matrix:
    """K exactly as the device holds it (its dtype's off-diagonal values, diagonal −Σ_J K_IJ), in float64."""
    n = op.n_vertices
    off = sp.csr_matrix((op._values.numpy().astype(np.float64), op._columns.numpy(), op._row_start.numpy()), shape=(n, n))
    return (off - sp.diags(np.asarray(off.sum(axis=1)).ravel())).tocsr()


def to_bsr(matrix: sp.csr_matrix, dtype: str, device):
    """A warp.sparse BsrMatrix (1×1 blocks) of a SciPy matrix, values rounded to dtype."""
    import warp.sparse as wsp

    coo = matrix.tocoo()
    rows = wp.array(coo.row.astype(np.int32), device=device)
    columns = wp.array(coo.col.astype(np.int32), device=device)
    values = wp.array(coo.data.astype(dtype), device=device)
    bsr = wsp.bsr_from_triplets(matrix.shape[0], matrix.shape[1], rows, columns, values)
    bsr.nnz_sync()  # bsr_from_triplets leaves nnz at the triplet count until synchronised
    return bsr


def relative(a, b) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


# ---------------------------------------------------------------------------------------------- CG
class OurOperator:
    """(M + s K) as a warp.optim.linear.LinearOperator through our K action (op.apply_device)."""

    def __init__(self, op, shift):
        import warp.optim.linear as wol

        self.op, self.shift = op, op.scalar(shift)
        self.Kx = wp.empty(op.n_vertices, dtype=op.scalar, device=op.device)
        n = op.n_vertices
        self.linear_operator = wol.LinearOperator((n, n), op.scalar, op.device, self.matvec)

    def matvec(self, x, y, z, alpha, beta):
        op, s = self.op, self.op.scalar
        op.apply_device(x, self.Kx)
        wp.launch(shifted_matvec_kernel, dim=op.n_vertices,
                  inputs=[x, self.Kx, op.mass_device, self.shift, s(alpha), s(beta), y], outputs=[z], device=op.device)  # fmt: skip


class CGCase:
    """One (M + s K) x = b problem and its three solvers, each with its own x, prepared once."""

    def __init__(self, level: int, dtype: str, device):
        import warp.optim.linear as wol

        from wavewarp.initial import gaussian_pulse
        from wavewarp.shifted_solve import ShiftedMassSolver

        self.level, self.dtype, self.device = level, dtype, device
        self.op = op = operator(level, dtype, device)
        self.n, self.tol, self.shift = op.n_vertices, CG_TOL[dtype], DT * GAMMA**2
        c0, _ = gaussian_pulse(op, 0, 0.3, gamma=1.0)
        mass = op.mass_device.numpy().astype(np.float64)
        self.x0 = c0.astype(dtype)
        self.b_host = (mass * (c0 + DT * c0 * (1 - c0) * (c0 - NU))).astype(dtype)
        self.matrix = (sp.diags(mass) + self.shift * device_stiffness(op)).tocsr()  # float64 of the device's values
        self.reference = sla.spsolve(self.matrix.tocsc(), self.b_host.astype(np.float64))
        self.capture = wp.get_device(device).is_cuda and wp.is_conditional_graph_supported()
        with wp.ScopedDevice(device):
            self.b = wp.array(self.b_host, dtype=op.scalar)
            self.x = {name: wp.array(self.x0, dtype=op.scalar) for name in CG_SOLVERS}
        self.build_seconds, self.runs, self.iteration_arrays, self.graphs = {}, {}, {}, {}
        maxiter = 1000
        check_every = 0 if self.capture else 1

        start = time.perf_counter()
        self.ours = ShiftedMassSolver(op, self.tol, maxiter)
        self.ours.prepare(self.shift)
        self.build_seconds["ours"] = time.perf_counter() - start
        self.runs["ours"] = lambda: self.ours.solve(self.b, self.x["ours"])
        self.iteration_arrays["ours"] = self.ours.iteration

        start = time.perf_counter()
        self.bsr = to_bsr(self.matrix, dtype, device)
        bsr_state = wol.cg(self.bsr, self.b, self.x[CG_SOLVERS[1]], tol=self.tol, atol=0.0, maxiter=maxiter,
                           M=wol.preconditioner(self.bsr, "diag"), check_every=check_every, run=False)  # fmt: skip
        self.build_seconds[CG_SOLVERS[1]] = time.perf_counter() - start

        start = time.perf_counter()
        self.wrapped = OurOperator(op, self.shift)
        preconditioner = wol.aslinearoperator(self.ours.inverse_diagonal)  # 1 / (M + s diag K), as ours
        op_state = wol.cg(self.wrapped.linear_operator, self.b, self.x[CG_SOLVERS[2]], tol=self.tol, atol=0.0,
                          maxiter=maxiter, M=preconditioner, check_every=check_every, run=False)  # fmt: skip
        self.build_seconds[CG_SOLVERS[2]] = time.perf_counter() - start
        for name, state in ((CG_SOLVERS[1], bsr_state), (CG_SOLVERS[2], op_state)):
            self.runs[name] = self._warp_run(name, state)
        self.warp_state = bsr_state

    def default_atol(self) -> tuple[int, float]:
        """(iterations, true relative residual) of Warp's cg on the BsrMatrix with atol left at its default
        (= tol, an absolute bound): a pitfall, not timed."""
        import warp.optim.linear as wol

        x = wp.array(self.x0, dtype=self.op.scalar, device=self.device)
        iterations, _, _ = wol.cg(self.bsr, self.b, x, tol=self.tol, maxiter=1000, M=wol.preconditioner(self.bsr, "diag"),
                                  check_every=1)  # fmt: skip
        return int(iterations), self.residuals(x.numpy().astype(np.float64))[0]

    def dot_seconds(self, repeats: int) -> dict:
        """Seconds per dot product of two length-V vectors: ours (op.dot_device, strided partial sums and
        atomics) and Warp's CG reduction (its TiledDot, one column), the cost that separates the solvers."""
        a, out = self.x["ours"], wp.zeros(1, dtype=self.op.scalar, device=self.device)
        tiled = getattr(self.warp_state, "_tiled_dot", None)  # private in Warp 1.19: skipped if it moves
        functions = {"ours": lambda: self.op.dot_device(a, self.b, out)}
        if tiled is not None:
            functions["warp"] = lambda: tiled.compute(a, self.b)
        result = {}
        for name, function in functions.items():
            function()

            def batch(function=function):
                for _ in range(10):
                    function()

            result[name] = float(np.median([sync_timed(self.device, batch) for _ in range(repeats)])) / 10
        return result

    def _warp_run(self, name, state):
        def run():
            result = state()
            if isinstance(result[0], wp.array):  # check_every=0: device arrays
                self.iteration_arrays[name] = result[0]
            else:
                self.iteration_arrays[name] = int(result[0])

        return run

    def reset(self, name) -> None:
        self.x[name].assign(self.x0)

    def solve(self, name) -> None:
        """One solve from x0 (a captured graph on CUDA, captured on first use after a warm-up)."""
        self.reset(name)
        if not self.capture:
            self.runs[name]()
            return
        if name not in self.graphs:
            self.runs[name]()  # loads the modules
            self.reset(name)
            with wp.ScopedCapture(device=self.device) as scope:
                self.runs[name]()
            self.graphs[name] = scope.graph
            self.reset(name)
        wp.capture_launch(self.graphs[name])

    def iterations(self, name) -> int:
        value = self.iteration_arrays[name]
        return int(value.numpy()[0]) if isinstance(value, wp.array) else int(value)

    def timed_solve(self, name) -> float:
        self.reset(name)
        wp.synchronize_device(self.device)
        if self.capture:
            return sync_timed(self.device, lambda: wp.capture_launch(self.graphs[name]))  # captured by the warm-up
        return sync_timed(self.device, self.runs[name])

    def solution(self, name) -> np.ndarray:
        return self.x[name].numpy().astype(np.float64)

    def residuals(self, x) -> tuple[float, float]:
        """True relative residuals of x in float64: ‖b − A x‖₂ / ‖b‖₂ and in the Jacobi norm (ours)."""
        b = self.b_host.astype(np.float64)
        r = b - self.matrix @ x
        weight = 1.0 / self.matrix.diagonal()
        return float(np.linalg.norm(r) / np.linalg.norm(b)), float(np.sqrt((r * weight) @ r / ((b * weight) @ b)))


def cg_rows(level: int, dtype: str, device, repeats: int) -> list[dict]:
    case = CGCase(level, dtype, device)
    weight = 1.0 / case.matrix.diagonal()
    rows = []
    for name in CG_SOLVERS:
        case.solve(name)  # warm-up (and graph capture on CUDA)
        times = [case.timed_solve(name) for _ in range(repeats)]
        x = case.solution(name)
        residual, jacobi_residual = case.residuals(x)
        rows.append({"item": "cg", "level": level, "vertices": case.n, "dtype": dtype, "method": name,
                     "ms": 1e3 * float(np.median(times)), "iterations": case.iterations(name), "tol": case.tol,
                     "residual": residual, "jacobi_residual": jacobi_residual,
                     "error_vs_scipy": relative(x, case.reference), "build_seconds": case.build_seconds[name],
                     "norm_equivalence": float(np.sqrt(weight.max() / weight.min())),
                     "captured": case.capture})  # fmt: skip
    ours = case.solution("ours")
    dots = case.dot_seconds(repeats)
    iterations, residual = case.default_atol()
    for row in rows:
        row["difference_vs_ours"] = relative(case.solution(row["method"]), ours)
        key = "ours" if row["method"] == "ours" else "warp"
        row["dot_us"] = 1e6 * dots[key] if key in dots else None
        if row["method"] == CG_SOLVERS[1]:
            row["default_atol_iterations"], row["default_atol_residual"] = iterations, residual
    return rows


# -------------------------------------------------------------------------------------------- SpMV
class SpmvCase:
    """K x by our kernel and by warp.sparse.bsr_mv on the same K (the device's values)."""

    def __init__(self, level: int, dtype: str, device):
        self.op = op = operator(level, dtype, device)
        self.device, self.n = device, op.n_vertices
        self.K = device_stiffness(op)
        start = time.perf_counter()
        self.bsr = to_bsr(self.K, dtype, device)
        self.build_seconds = {"ours": 0.0, "warp bsr_mv": time.perf_counter() - start}
        rng = np.random.default_rng(1)
        from wavewarp.initial import gaussian_pulse

        self.inputs = {"random": rng.uniform(-1.0, 1.0, self.n).astype(dtype),
                       "smooth": gaussian_pulse(op, 0, 0.3, gamma=1.0)[0].astype(dtype)}  # fmt: skip
        with wp.ScopedDevice(device):
            self.x = wp.array(self.inputs["random"], dtype=op.scalar)
            self.y = {name: wp.zeros(self.n, dtype=op.scalar) for name in SPMV_METHODS}

    def product(self, name: str, x=None) -> None:
        import warp.sparse as wsp

        x = self.x if x is None else x
        if name == "ours":
            self.op.apply_device(x, self.y[name])
        else:
            wsp.bsr_mv(self.bsr, x, self.y[name], alpha=1.0, beta=0.0)

    def result(self, name: str, values: np.ndarray) -> np.ndarray:
        x = wp.array(values, dtype=self.op.scalar, device=self.device)
        self.product(name, x)
        return self.y[name].numpy().astype(np.float64)

    def seconds_per_product(self, name: str, min_seconds: float, repeats: int) -> float:
        """Median over `repeats` of a batch of products lasting ≥ min_seconds. On CUDA the batch
        replays a captured graph of GRAPH_PRODUCTS products (as a captured stepper runs them)."""
        self.product(name)  # warm-up
        unit, per_unit = (lambda: self.product(name)), 1
        if wp.get_device(self.device).is_cuda:
            with wp.ScopedCapture(device=self.device) as scope:
                for _ in range(GRAPH_PRODUCTS):
                    self.product(name)
            graph = scope.graph
            unit, per_unit = (lambda: wp.capture_launch(graph)), GRAPH_PRODUCTS
        count = 1
        while True:
            def batch(count=count):
                for _ in range(count):
                    unit()

            if sync_timed(self.device, batch) >= min_seconds or count >= 1 << 20:
                break
            count *= 2
        return float(np.median([sync_timed(self.device, batch) for _ in range(repeats)])) / (count * per_unit)


def spmv_rows(level: int, dtype: str, device, repeats: int, min_seconds: float) -> list[dict]:
    case = SpmvCase(level, dtype, device)
    rows, results = [], {}
    for name in SPMV_METHODS:
        seconds = case.seconds_per_product(name, min_seconds, repeats)
        row = {"item": "spmv", "level": level, "vertices": case.n, "nnz": int(case.K.nnz), "dtype": dtype, "method": name,
               "us": 1e6 * seconds, "build_seconds": case.build_seconds[name],
               "captured": wp.get_device(device).is_cuda}  # fmt: skip
        for kind, values in case.inputs.items():
            y = case.result(name, values)
            results[name, kind] = y
            row[f"error_vs_scipy_{kind}"] = relative(y, case.K @ values.astype(np.float64))
        rows.append(row)
    for row in rows:
        row["difference_vs_ours"] = relative(results[row["method"], "random"], results["ours", "random"])
    return rows


# ------------------------------------------------------------------------------------------ report
def ratios(rows: list[dict]) -> list[dict]:
    """Ours / Warp's time per configuration (> 1: Warp's is faster), from this run's rows."""
    out = []
    for item, key, methods in (("colouring", "seconds", COLOURINGS[1:]), ("cg", "ms", CG_SOLVERS[1:]),
                               ("spmv", "us", SPMV_METHODS[1:])):  # fmt: skip
        for row in rows:
            if row["item"] != item or row["method"] != "ours":
                continue
            for other in rows:
                same = all(other.get(k) == row.get(k) for k in ("item", "level", "dtype"))
                if same and other["method"] in methods:
                    entry = {"item": item, "level": row["level"], "vertices": row["vertices"], "dtype": row.get("dtype"),
                             "warp": other["method"], "ours_over_warp": row[key] / other[key]}  # fmt: skip
                    if item == "colouring":
                        entry["colours_ours"], entry["colours_warp"] = row["colours"], other["colours"]
                    out.append(entry)
    return out


def print_tables(rows: list[dict], device_alias: str) -> None:
    ours = {(r["item"], r["level"], r.get("dtype")): r for r in rows if r["method"] == "ours"}
    print(f"\ncolouring (host), distance-two colourings of the Newton pattern   [device {device_alias}]")
    print(f"{'L':>2} {'V':>7} {'method':24s} {'seconds':>9} {'ours/this':>9} {'colours':>7} {'bound':>5} {'valid':>5} {'max/min':>7}")
    for r in (r for r in rows if r["item"] == "colouring"):
        ratio = ours["colouring", r["level"], None]["seconds"] / r["seconds"]
        print(f"{r['level']:>2} {r['vertices']:>7} {r['method']:24s} {r['seconds']:9.4f} {ratio:9.2f} {r['colours']:>7} "
              f"{r['lower_bound']:>5} {str(r['valid']):>5} {r['max_min_group_ratio']:7.2f}")  # fmt: skip
    print("\nCG for (M + s K) x = b, s = 0.02, Jacobi preconditioner")
    print(f"{'L':>2} {'V':>7} {'dtype':7s} {'solver':20s} {'ms/solve':>9} {'ours/this':>9} {'iters':>5} {'‖r‖/‖b‖':>9} "
          f"{'P-norm':>9} {'err/scipy':>9} {'diff/ours':>9} {'µs/dot':>8}")  # fmt: skip
    for r in (r for r in rows if r["item"] == "cg"):
        ratio = ours["cg", r["level"], r["dtype"]]["ms"] / r["ms"]
        print(f"{r['level']:>2} {r['vertices']:>7} {r['dtype']:7s} {r['method']:20s} {r['ms']:9.3f} {ratio:9.3f} "
              f"{r['iterations']:>5} {r['residual']:9.2e} {r['jacobi_residual']:9.2e} {r['error_vs_scipy']:9.2e} "
              f"{r['difference_vs_ours']:9.2e} {r['dot_us'] or float('nan'):8.1f}")  # fmt: skip
    for r in (r for r in rows if "default_atol_iterations" in r):
        print(f"  pitfall, L{r['level']} {r['dtype']}: Warp's cg with atol left at its default (= tol, absolute) stops after "
              f"{r['default_atol_iterations']} iterations at ‖r‖/‖b‖ = {r['default_atol_residual']:.2e} "
              f"(atol=0: {r['iterations']}, {r['residual']:.2e})")  # fmt: skip
    print("\nK x (sparse product), 1×1 blocks")
    print(f"{'L':>2} {'V':>7} {'dtype':7s} {'method':12s} {'µs/product':>10} {'ours/this':>9} {'err random':>10} "
          f"{'err smooth':>10} {'diff/ours':>9}")  # fmt: skip
    for r in (r for r in rows if r["item"] == "spmv"):
        ratio = ours["spmv", r["level"], r["dtype"]]["us"] / r["us"]
        print(f"{r['level']:>2} {r['vertices']:>7} {r['dtype']:7s} {r['method']:12s} {r['us']:10.1f} {ratio:9.3f} "
              f"{r['error_vs_scipy_random']:10.2e} {r['error_vs_scipy_smooth']:10.2e} {r['difference_vs_ours']:9.2e}")  # fmt: skip


def chart(result: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wavewarp.io import write_png

    rows = result["rows"]
    fig, (left, middle, right) = plt.subplots(1, 3, figsize=(17, 5))
    colouring = [r for r in rows if r["item"] == "colouring"]
    levels = sorted({r["level"] for r in colouring})
    width = 0.8 / len(COLOURINGS)
    for k, method in enumerate(COLOURINGS):
        values = [next(r for r in colouring if r["level"] == level and r["method"] == method) for level in levels]
        bars = left.bar(np.arange(len(levels)) + k * width, [r["colours"] for r in values], width, label=method)
        for bar, r in zip(bars, values):
            left.annotate(f"{1e3 * r['seconds']:.0f} ms", (bar.get_x() + width / 2, bar.get_height()), fontsize=6,
                          ha="center", va="bottom", rotation=90)  # fmt: skip
    bound = max(r["lower_bound"] for r in colouring)
    left.axhline(bound, color="k", lw=0.8, ls=":", label=f"lower bound (largest row of P: {bound})")
    left.plot([], [], " ", label="(above bars: wall ms)")
    left.set_ylim(0, 1.6 * max(r["colours"] for r in colouring))
    left.set_xticks(np.arange(len(levels)) + 0.4 - width / 2, [f"L{level}" for level in levels])
    left.set_ylabel("colours (each costs 6 force evaluations)")
    left.set_title("distance-two colouring of the Newton pattern")
    left.legend(fontsize=7, loc="upper center", ncol=2)
    for axis, item, key, methods, label in ((middle, "cg", "ms", CG_SOLVERS, "ms per solve"),
                                            (right, "spmv", "us", SPMV_METHODS, "µs per product")):  # fmt: skip
        for method in methods:
            for dtype, style in (("float32", "-"), ("float64", "--")):
                series = sorted((r["vertices"], r[key]) for r in rows if r["item"] == item and r["method"] == method
                                and r["dtype"] == dtype)  # fmt: skip
                if series:
                    axis.loglog(*zip(*series), "o" + style, label=f"{method}, {dtype}")
        axis.set_xlabel("vertices")
        axis.set_ylabel(label)
        axis.legend(fontsize=7)
    middle.set_title("CG for (M + s K) x = b (Jacobi, same tol)")
    right.set_title("K x: our gather kernel against bsr_mv")
    fig.suptitle(f"wavewarp: Warp's libraries against ours, {result['device_name']} ({result['date']})")
    fig.tight_layout()
    write_png(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench warp_libraries", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present, else cpu)")
    parser.add_argument("--out", default=".")
    parser.add_argument("--quick", action="store_true", help="levels 3-4 and fewer repeats (seconds)")
    parser.add_argument("--repeats", type=int, default=None, help="timed repeats per figure (default 5, quick 3)")
    args = parser.parse_args(argv)
    from wavewarp.device import describe_device
    from wavewarp.io import write_json

    os.makedirs(args.out, exist_ok=True)
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    device = wp.get_device(args.device or ("cuda:0" if wp.is_cuda_available() else "cpu"))
    repeats = args.repeats or (3 if args.quick else 5)
    colouring_levels, cg_levels = ([3, 4], [3, 4]) if args.quick else ([3, 4, 5], [3, 4, 5])
    spmv_levels, min_seconds = ([3, 4], 0.02) if args.quick else ([3, 4, 5, 6], 0.2)
    rows = []
    for level in colouring_levels:
        rows += colouring_rows(level, repeats)
        print(f"colouring L{level} done", flush=True)
    for level in cg_levels:
        for dtype in DTYPES:
            rows += cg_rows(level, dtype, device.alias, repeats)
            print(f"CG L{level} {dtype} done", flush=True)
    for level in spmv_levels:
        for dtype in DTYPES:
            rows += spmv_rows(level, dtype, device.alias, repeats, min_seconds)
            print(f"K x L{level} {dtype} done", flush=True)
    print_tables(rows, device.alias)
    result = {
        "benchmark": "warp_libraries", "date": date.today().isoformat(), **describe_device(device), "quick": args.quick,
        "repeats": repeats,
        "cg_stopping": "ours: r·P r <= tol² b·P b (P = 1/diag(M + sK)), every iteration; warp: ‖r‖₂ <= max(tol ‖b‖₂, atol) "
                       "with atol=0 (floored by Warp at eps^(9/4)), check_every=1 on the CPU, 0 (device-side) on CUDA; "
                       "same tol, b and x0; 'residual' / 'jacobi_residual' are the true residuals of each result",
        "rows": rows, "ratios": ratios(rows),
    }  # fmt: skip
    print("\nours / Warp's time (> 1: Warp's is faster):")
    for entry in result["ratios"]:
        extra = f"  colours {entry['colours_ours']} vs {entry['colours_warp']}" if entry["item"] == "colouring" else ""
        print(f"  {entry['item']:9s} L{entry['level']} {entry['dtype'] or 'host':7s} vs {entry['warp']:26s}: "
              f"{entry['ours_over_warp']:7.3f}{extra}")  # fmt: skip
    json_path = os.path.join(args.out, "warp_libraries.json")
    write_json(json_path, result)
    png_path = os.path.join(args.out, "warp_libraries.png")
    chart(result, png_path)
    print(f"wrote {json_path} and {png_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
