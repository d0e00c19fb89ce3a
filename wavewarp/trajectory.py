"""HDF5 trajectories (docs/theory/scenes.md): written atomically, frame by frame, and resumable.

Schema: `/mesh/triangles` (T, 3), `/mesh/rest_positions` (V, 3); `/frames/time` (F,),
`/frames/positions` (F, V, 3), `/frames/concentration` (F, V) and any further per-vertex
series a scene records (`velocities` (F, V, 3), `inhibitor` (F, V); the walkers' `reaction_amount`
(F,), the amount the reaction has added, `first_arrival` (F, V), each vertex's first-front arrival,
and `trace` (F, k, 8): time, c at the origin, the centre of mass and the origin vertex's position at
the k chemistry steps up to each frame);
root attributes `scene`, `parameters` (JSON), `wavewarp_version`, `device`, and at the end of a
run `measurements` (JSON) plus each numeric measurement under its own name (walkers: `period`,
`distance_R`, `speed_R_per_T`, ...).

Frames go to a temporary sibling that replaces the target when the writer closes, also after
Ctrl-C (the frames so far are kept); any other error removes it and leaves the target as it
was. `resume=True` continues an existing file: its frames are copied and new ones appended.
"""

from __future__ import annotations

import json
import os
import shutil

import numpy as np

from .io import atomic_path
from .version import __version__


def _check_frame(name: str, values: np.ndarray) -> None:
    if not np.all(np.isfinite(values)):
        raise ValueError(f"refusing to write a frame with non-finite {name}")


class TrajectoryWriter:
    """Context manager appending frames to an HDF5 trajectory.

    `series` maps each per-frame dataset beyond time to its per-frame shape, e.g.
    {"positions": (V, 3), "concentration": (V,)}.
    """

    def __init__(self, path, *, triangles, rest_positions, series: dict, scene: str, parameters: dict, device: str,
                 resume: bool = False):  # fmt: skip
        if os.path.splitext(os.fspath(path))[1] not in (".h5", ".hdf5"):
            raise ValueError(f"HDF5 output {os.fspath(path)!r} must end in .h5 or .hdf5")
        self.path = os.fspath(path)
        self.triangles = np.asarray(triangles, dtype=np.int32)
        self.rest_positions = np.asarray(rest_positions, dtype=np.float64)
        self.series = {name: tuple(shape) for name, shape in series.items()}
        self.attributes = {"scene": scene, "parameters": json.dumps(parameters, sort_keys=True),
                           "wavewarp_version": __version__, "device": str(device)}  # fmt: skip
        self.resume = bool(resume)
        self.frames = 0

    def __enter__(self) -> TrajectoryWriter:
        import h5py

        self._atomic = atomic_path(self.path)
        self._tmp = self._atomic.__enter__()
        try:
            if self.resume:
                shutil.copyfile(self.path, self._tmp)
                self.file = h5py.File(self._tmp, "r+")
                self._check_resumable()
                self.frames = len(self.file["frames/time"])
                self.file.attrs["parameters"] = self.attributes["parameters"]
                self.file.attrs["device"] = self.attributes["device"]
            else:
                self.file = h5py.File(self._tmp, "w")
                self._create()
        except BaseException as error:
            self._atomic.__exit__(type(error), error, error.__traceback__)
            raise
        return self

    def _create(self) -> None:
        f = self.file
        for key, value in self.attributes.items():
            f.attrs[key] = value
        f.create_dataset("mesh/triangles", data=self.triangles)
        f.create_dataset("mesh/rest_positions", data=self.rest_positions)
        f.create_dataset("frames/time", shape=(0,), maxshape=(None,), dtype=np.float64, chunks=(256,))
        for name, shape in self.series.items():
            f.create_dataset(f"frames/{name}", shape=(0, *shape), maxshape=(None, *shape), dtype=np.float64,
                             chunks=(1, *shape))  # fmt: skip

    def _check_resumable(self) -> None:
        f = self.file
        if f.attrs.get("scene") != self.attributes["scene"]:
            raise ValueError(f"cannot resume {self.path!r}: it holds scene {f.attrs.get('scene')!r}, "
                             f"not {self.attributes['scene']!r}")  # fmt: skip
        if not np.array_equal(f["mesh/triangles"][...], self.triangles):
            raise ValueError(f"cannot resume {self.path!r}: its mesh differs from this run's (same --mesh and level?)")
        for name, shape in self.series.items():
            if f"frames/{name}" not in f or f[f"frames/{name}"].shape[1:] != shape:
                raise ValueError(f"cannot resume {self.path!r}: frames/{name} is missing or has another shape")
        if len(f["frames/time"]) == 0:
            raise ValueError(f"cannot resume {self.path!r}: it has no frames")

    def add_frame(self, time: float, frame: dict) -> None:
        """Append one frame (the writers' protocol): the time and every series given at construction."""
        values = frame
        if set(values) != set(self.series):
            raise ValueError(f"a frame needs exactly {sorted(self.series)}, got {sorted(values)}")
        arrays = {name: np.asarray(v, dtype=np.float64) for name, v in values.items()}
        for name, array in arrays.items():
            _check_frame(name, array)
        n = self.frames + 1
        self.file["frames/time"].resize((n,))
        self.file["frames/time"][n - 1] = float(time)
        for name, array in arrays.items():
            dataset = self.file[f"frames/{name}"]
            dataset.resize((n, *dataset.shape[1:]))
            dataset[n - 1] = array
        self.file.flush()
        self.frames = n

    def set_measurements(self, measured: dict) -> None:
        """Root attributes: `measurements` (JSON) and each numeric measurement by name."""
        self.file.attrs["measurements"] = json.dumps(measured, sort_keys=True)
        for name, value in measured.items():
            if isinstance(value, (bool, int, float)) or (isinstance(value, list) and value and all(
                    isinstance(v, (int, float)) for v in value)):  # fmt: skip
                self.file.attrs[name] = value
        self.file.flush()

    def __exit__(self, kind, error, trace) -> bool:
        self.file.close()
        keep = kind is None or (issubclass(kind, KeyboardInterrupt) and self.frames > 0)
        if keep:
            self._atomic.__exit__(None, None, None)
        else:
            self._atomic.__exit__(kind or RuntimeError, error, trace)
        return False


def last_frame(path) -> dict:
    """The last frame of a trajectory as {"time": t, name: array, ...} plus "frames" (the count)."""
    import h5py

    with h5py.File(os.fspath(path), "r") as f:
        frames = f["frames"]
        count = len(frames["time"])
        if count == 0:
            raise ValueError(f"{os.fspath(path)!r} has no frames to resume from")
        out = {name: frames[name][count - 1] for name in frames}
        out["time"] = float(out["time"])
        out["frames"] = count
        return out
