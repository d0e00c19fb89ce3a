"""Benchmarks, run as `wavewarp bench NAME` (or `python benchmarks/NAME.py`); each writes JSON and a PNG chart."""

NAMES = ("accuracy", "chemistry", "limit_surface", "locomotion", "shell", "speed", "stability")  # modules with main(argv); numpy_shell is a baseline
