"""The package's shape: imports go one way (no cycle, function-local imports included) and no module
grows past MAX_LINES. Read from the source with `ast`, so a cycle hidden inside a function counts."""

import ast
import os

import pytest

ROOT = os.path.join(os.path.dirname(__file__), os.pardir)
PACKAGES = {"wavewarp": "wavewarp", "wavewarp.kernels": "kernels", "wavewarp.scenes": "scenes",
            "wavewarp.benchmarks": "benchmarks"}  # fmt: skip
MAX_LINES = 600


def modules() -> dict:
    """Dotted module name -> source path, for every module of the installed packages."""
    found = {}
    for package, folder in PACKAGES.items():
        for name in sorted(os.listdir(os.path.join(ROOT, folder))):
            if name.endswith(".py"):
                stem = name[:-3]
                found[package if stem == "__init__" else f"{package}.{stem}"] = os.path.join(ROOT, folder, name)
    return found


def imported(module: str, path: str, known: set) -> set:
    """The package modules `module` imports anywhere in its source (module level or inside functions)."""
    tree = ast.parse(open(path).read())
    package = module if path.endswith("__init__.py") else module.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{base}.{node.module}" if node.module else base
            else:
                base = node.module
            # `from package import submodule` imports the submodule, not the package's own names
            names = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
        else:
            continue
        for name in names:
            while name and name not in known:
                name = name.rpartition(".")[0]
            if name and name != module:
                out.add(name)
    return out


def test_imports_have_no_cycle():
    found = modules()
    graph = {name: imported(name, path, set(found)) for name, path in found.items()}
    state, stack = {}, []

    def visit(name):
        state[name] = "open"
        stack.append(name)
        for target in sorted(graph[name]):
            if state.get(target) == "open":
                cycle = stack[stack.index(target):] + [target]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if target not in state:
                visit(target)
        stack.pop()
        state[name] = "done"

    for name in sorted(graph):
        if name not in state:
            visit(name)


@pytest.mark.parametrize("module", sorted(modules()))
def test_no_module_grows_past_the_limit(module):
    lines = sum(1 for _ in open(modules()[module]))
    assert lines <= MAX_LINES, f"{module} has {lines} lines (at most {MAX_LINES}): split it"
