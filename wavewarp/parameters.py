"""Typed scene parameters and the scene registry.

A scene's parameters are a frozen dataclass whose fields are declared with `param(default, help,
...)`: the default fixes the type, the help is one line of meaning, and the checks (choices,
positive, minimum) say what is valid. `resolve(defaults, quick, overrides)` applies a scene's quick
settings and `--set NAME=VALUE` overrides; an unknown name or a bad value raises `SceneError`
listing what is valid. A trajectory stores `as_dict(p)`, and `resumed(type, stored)` rebuilds the
parameters of the run it holds (a parameter newer than the file takes its `legacy` value).

A scene script (`scenes/NAME.py`, installed as `wavewarp.scenes`) defines `NAME`, `DESCRIPTION`,
`Parameters` (the dataclass), `QUICK` (the `--quick` overrides) and `build(p, *, mesh, device,
seed, report)`, which returns a run (see wavewarp/driver.py).
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.util
import math
import os
import pkgutil

from . import scenes


class SceneError(ValueError):
    """A scene name, parameter or value that cannot be used; the message lists what is valid."""


def param(default, help: str, *, choices=(), positive: bool = False, minimum=None, legacy=None, auto: bool = False,
          even: bool = False, infinite: bool = False):  # fmt: skip
    """A scene parameter: its default (which fixes its type), one line of help, what values are valid,
    and `legacy`, the value a trajectory written before the parameter existed ran with. `auto`: a number
    whose 0 means "chosen automatically"; `--set NAME=auto` gives that 0. `even`: an even integer.
    `infinite`: a number that may also be inf."""
    check = {"help": help, "choices": tuple(choices), "positive": positive, "minimum": minimum, "legacy": legacy,
             "auto": auto, "even": even, "infinite": infinite}  # fmt: skip
    return dataclasses.field(default=default, metadata=check)


def fields(kind) -> dict:
    """name -> dataclasses.Field of a parameters type (or instance)."""
    return {f.name: f for f in dataclasses.fields(kind)}


def parse(field: dataclasses.Field, text):
    """`text` as the field's type, checked: SceneError naming the parameter and what is valid."""
    name, kind, check = field.name, type(field.default), field.metadata
    if check.get("auto") and str(text).strip().lower() == "auto":
        return kind(0)
    try:
        if kind is bool:
            value = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}[str(text).lower()]
        elif kind is int:
            value = int(text)
        elif kind is float:
            value = float(text)
            if not (math.isfinite(value) or (check.get("infinite") and value == math.inf)):
                raise ValueError
        else:
            value = str(text)
    except (KeyError, ValueError):
        expected = {bool: "true or false", int: "an integer",
                    float: "a number or inf" if check.get("infinite") else "a finite number"}.get(kind, "text")  # fmt: skip
        expected += " or auto" if check.get("auto") else ""
        raise SceneError(f"bad value for {name}: {text!r} (expected {expected})") from None
    if check["choices"] and value not in check["choices"]:
        raise SceneError(f"bad value for {name}: {value!r} (one of {', '.join(map(str, check['choices']))})")
    if check["positive"] and not value > 0:
        raise SceneError(f"bad value for {name}: {value!r} (must be > 0)")
    if check["minimum"] is not None and value < check["minimum"]:
        raise SceneError(f"bad value for {name}: {value!r} (must be >= {check['minimum']})")
    if check.get("even") and value % 2:
        raise SceneError(f"bad value for {name}: {value!r} (must be even, e.g. {value + 1})")
    return value


def resolve(kind, quick: dict | None = None, overrides=()):
    """Defaults of the parameters type `kind`, then `quick`, then NAME=VALUE `overrides` (SceneError
    for an unknown name or a bad value)."""
    known = fields(kind)
    values = dict(quick or {})
    for item in overrides:
        name, sep, text = str(item).partition("=")
        name = name.strip()
        if not sep:
            raise SceneError(f"--set needs NAME=VALUE, got {item!r}")
        if name not in known:
            raise SceneError(f"unknown parameter {name!r}; valid: {', '.join(sorted(known))}")
        values[name] = parse(known[name], text.strip())
    return kind(**values)


def resumed(kind, stored: dict):
    """The parameters a stored trajectory ran with: its values for the fields it has; for newer fields,
    the value such files ran with (`legacy`), else the default. Stored keys that are no parameters
    (derived values) are left out."""
    values = {name: f.metadata["legacy"] for name, f in fields(kind).items() if f.metadata.get("legacy") is not None}
    values.update({name: value for name, value in stored.items() if name in fields(kind)})
    return kind(**values)


def as_dict(p) -> dict:
    """The parameters as a plain dict (JSON for trajectories and `--json`)."""
    return dataclasses.asdict(p)


def help_lines(kind) -> list:
    """One line per parameter: name, default and help (for `wavewarp run SCENE --help`)."""
    return [f"{name} = {_shown(f)}: {f.metadata['help']}" for name, f in fields(kind).items()]


def _shown(field: dataclasses.Field) -> str:
    return "auto" if field.metadata.get("auto") and field.default == 0 else repr(field.default)


# ---------------------------------------------------------------- the scene registry


def scene_descriptions() -> dict[str, str]:
    """Scene name -> one-line description, from the modules of `wavewarp.scenes`."""
    found = {}
    for info in pkgutil.iter_modules(scenes.__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"wavewarp.scenes.{info.name}")
        found[getattr(module, "NAME", info.name.replace("_", "-"))] = getattr(module, "DESCRIPTION", "")
    return dict(sorted(found.items()))


def _scene_script(path: str):
    """The module of the scene script `path`; SceneError where it is missing, not Python or fails to load."""
    if not os.path.isfile(path):
        raise SceneError(f"scene script {path!r} does not exist")
    if not path.endswith(".py"):
        raise SceneError(f"scene script {path!r} is not a Python file (.py): give a scene name (wavewarp list) or a "
                         "script that defines NAME, Parameters and build")
    spec = importlib.util.spec_from_file_location("wavewarp_user_scene", path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except SyntaxError as error:
        if error.lineno is None:  # null bytes: a binary file
            raise SceneError(f"scene script {path!r} is not a Python text file ({error.msg})") from None
        raise SceneError(f"scene script {path!r} is not valid Python: {error.msg} (line {error.lineno})") from None
    except ValueError as error:  # e.g. null bytes or bytes that are no UTF-8: a binary file
        raise SceneError(f"scene script {path!r} is not a Python text file ({error})") from None
    except Exception as error:  # the script's own failure, in one line
        raise SceneError(f"scene script {path!r} failed to load: {type(error).__name__}: {error}") from None
    return module


def load_scene(name_or_path: str):
    """The scene module: a name from `wavewarp.scenes` or the path of a scene script."""
    if name_or_path.endswith(".py") or os.sep in name_or_path:
        module = _scene_script(name_or_path)
    else:
        known = scene_descriptions()
        if name_or_path not in known:
            raise SceneError(f"unknown scene {name_or_path!r}; valid: {', '.join(known)}")
        module = importlib.import_module(f"wavewarp.scenes.{name_or_path.replace('-', '_')}")
    for attribute in ("NAME", "Parameters", "build"):
        if not hasattr(module, attribute):
            raise SceneError(f"scene {name_or_path!r} defines no {attribute}")
    return module
