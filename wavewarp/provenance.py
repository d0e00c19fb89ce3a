"""A run's provenance in its HDF5 trajectory (root attributes), and the check that a resume continues the same
run (docs/theory/scenes.md "Resume").

Stored at creation: `seed`, `command_line`, `mesh_source` (the --mesh file, or the scene's own mesh),
`mesh_sha256` and `rest_positions_sha256` (SHA-256 of the stored arrays: triangles as little-endian int32,
rest positions as little-endian float64, each prefixed by its shape), `frames_planned` (the frames of the
whole run, the first included) and `wavewarp_version`. A resume refuses a file whose scene, version, seed,
mesh or rest shape differ from the run it would continue.
"""

from __future__ import annotations

import hashlib
import shlex

import numpy as np

from .version import __version__

SCENE_MESH = "the scene's own mesh"  # the mesh_source of a run without --mesh


def digest(array, dtype) -> str:
    """SHA-256 (hex) of `array` as little-endian `dtype`, prefixed by its shape: equal arrays, equal digests."""
    values = np.ascontiguousarray(np.asarray(array, dtype=np.dtype(dtype).newbyteorder("<")))
    return hashlib.sha256(repr(values.shape).encode() + values.tobytes()).hexdigest()


def mesh_digests(triangles, rest_positions) -> dict:
    return {"mesh_sha256": digest(triangles, np.int32), "rest_positions_sha256": digest(rest_positions, np.float64)}


def command_line(arguments) -> str:
    """`wavewarp ARGUMENTS...` as a shell would take it back."""
    return shlex.join(["wavewarp", *map(str, arguments)])


def resume_mismatch(stored: dict, run: dict) -> str | None:
    """What differs between a trajectory's root attributes `stored` and the run `run` that would continue it
    (the same keys: scene, wavewarp_version, seed, mesh_sha256, rest_positions_sha256), as
    "what differs: how to fix it"; None when they agree. Attributes a file from before them lacks are not
    compared (its stored mesh and rest shape still are, by their digests)."""
    source = stored.get("mesh_source", "")
    mesh_hint = f"pass --mesh {source}" if source and source != SCENE_MESH else "run without --mesh"
    checks = [
        ("scene", lambda a, b: f"it holds scene {a!r}, not {b!r}: resume it with wavewarp run {a} --resume"),
        ("wavewarp_version", lambda a, b: f"it was written by wavewarp {a}, this is {b}: finish it with wavewarp {a}, "
                                          "or start a new run (--overwrite)"),
        ("seed", lambda a, b: f"it ran with --seed {a}, not {b}: resume with --seed {a} (or leave --seed out)"),
        ("mesh_sha256", lambda a, b: f"its mesh differs from this run's ({stored.get('mesh_source', 'unknown')}): "
                                     f"{mesh_hint} as the run did"),
        ("rest_positions_sha256", lambda a, b: "its rest shape differs from this run's (another --seed, --mesh or "
                                               f"noise): {mesh_hint} and --seed {stored.get('seed', 'N')} as the "
                                               "run did"),
    ]
    for key, message in checks:
        if key in stored and key in run and str(stored[key]) != str(run[key]):
            return message(stored[key], run[key])
    return None


def run_provenance(*, seed: int, mesh_path: str | None, frames: int, arguments) -> dict:
    """The root attributes a new trajectory records beyond the scene and parameters (the mesh digests are
    the writer's): `arguments` are the command's, after `wavewarp`."""
    return {"seed": int(seed), "command_line": command_line(arguments), "mesh_source": mesh_path or SCENE_MESH,
            "frames_planned": int(frames), "wavewarp_version": __version__}
