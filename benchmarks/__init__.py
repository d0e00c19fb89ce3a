"""Benchmarks, run as `wavewarp bench NAME` (or `python benchmarks/NAME.py`); each writes JSON (most a PNG chart too)."""

NAMES = ("accuracy", "adjoint_cost", "adjoint_horizon", "batch", "buckling_mobility", "buckling_phase_diagram", "buckling_stability", "chemistry", "convergence", "fig3a", "gradient_cost", "gradient_horizon", "implicit_mechanics", "inverse_design", "kernel_registers", "limit_surface",
         "locomotion",
         "locomotion_ensemble", "numbering",
         "quasi_static_crawler", "quick_identity", "shell", "soak", "speed", "stability", "sweep_scaling", "tape_adjoints", "walker_regimes", "warp_libraries")  # fmt: skip  # modules with main(argv); numpy_shell is a baseline
