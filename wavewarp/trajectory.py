"""HDF5 trajectories (docs/theory/scenes.md): written atomically, frame by frame, and resumable.

Schema: `/mesh/triangles` (T, 3), `/mesh/rest_positions` (V, 3); `/frames/time` (F,),
`/frames/positions` (F, V, 3), `/frames/concentration` (F, V) and any further per-vertex
series a scene records (`velocities` (F, V, 3), `inhibitor` (F, V); the walkers' `reaction_amount`
(F,), the amount the reaction has added, `first_arrival` (F, V), each vertex's first-front arrival,
and `trace` (F, k, 8): time, c at the origin, the centre of mass and the origin vertex's position at
the k chemistry steps up to each frame; the quasi-static scenes' `relaxation_count` (F,),
`relaxation_times` (F, k) and `relaxation_concentration` (F, k, V), the arrival times' samples at the
relaxations since the previous frame);
root attributes `scene`, `parameters` (JSON), `wavewarp_version`, `device`, the provenance a resume
checks (wavewarp/provenance.py: `seed`, `command_line`, `mesh_source`, `mesh_sha256`,
`rest_positions_sha256`, `frames_planned`; a resume adds its command to `resumed_by`, JSON) (a sweep's
point also `sweep_batch`, its batch's points), and at the end of a run `measurements` (JSON) plus each
numeric measurement under its own name (walkers: `period`, `distance_R`, `speed_R_per_T`, ...). Every
dataset carries `units` and a one-line `description` (wavewarp/schema.py).

Durable frame by frame: a new file is created as a temporary sibling and renamed into place with
its first frame (an error before it leaves any older file untouched); from then on each frame is
appended in place, counted in the `/frames` attribute `complete` and synced to disk, so after a
kill -9 or a power cut the file holds every completed frame and `resume=True` continues it
(`frames` beyond `complete`, half-written when the process died, are cut first). A file whose count
exceeds the frames its datasets hold, or that lacks what a trajectory has, is refused in one line.
"""

from __future__ import annotations

import json
import os

import h5py
import numpy as np

from .io import check_writable, move_into_place, remove_stale_temporaries, temporary_file
from .provenance import mesh_digests, resume_mismatch
from .schema import dataset_attributes
from .version import __version__

COMPLETE = "complete"  # the /frames attribute: how many frames are whole


def _check_frame(name: str, values: np.ndarray) -> None:
    if not np.all(np.isfinite(values)):
        raise ValueError(f"refusing to write a frame with non-finite {name}")


class TrajectoryWriter:
    """Context manager appending frames to an HDF5 trajectory.

    `series` maps each per-frame dataset beyond time to its per-frame shape, e.g.
    {"positions": (V, 3), "concentration": (V,)}. `attributes`: further root attributes (strings).
    `provenance`: the run's (wavewarp/provenance.py `run_provenance`), stored in a new file and compared
    on a resume. `resume`: continue the file's frames; `resume_frames`: after at most this many (any
    beyond are cut).
    """

    def __init__(self, path, *, triangles, rest_positions, series: dict, scene: str, parameters: dict, device: str,
                 resume: bool = False, resume_frames: int | None = None, attributes: dict | None = None,
                 provenance: dict | None = None):
        if os.path.splitext(os.fspath(path))[1] not in (".h5", ".hdf5"):
            raise ValueError(f"HDF5 output {os.fspath(path)!r} must end in .h5 or .hdf5")
        self.path = os.fspath(path)
        self.triangles = np.asarray(triangles, dtype=np.int32)
        self.rest_positions = np.asarray(rest_positions, dtype=np.float64)
        self.series = {name: tuple(shape) for name, shape in series.items()}
        self.attributes = {"scene": scene, "parameters": json.dumps(parameters, sort_keys=True),
                           "wavewarp_version": __version__, "device": str(device),
                           **mesh_digests(self.triangles, self.rest_positions), **(provenance or {}),
                           **(attributes or {})}
        self.resume, self.resume_frames = bool(resume), resume_frames
        self.frames = 0

    def __enter__(self) -> TrajectoryWriter:
        self._pending = None
        if self.resume:
            check_writable(self.path)
            remove_stale_temporaries(self.path)
            try:
                self.file = h5py.File(self.path, "r+")
            except OSError as error:
                raise ValueError(f"cannot resume {self.path!r}: not a readable HDF5 trajectory ({error})") from None
            try:
                self._check_resumable(self.file)
                self.frames = complete_frames(self.file)
                if self.resume_frames is not None:
                    self.frames = min(self.frames, int(self.resume_frames))
                for name in self.file["frames"]:  # a frame half-written when the process died (or cut)
                    dataset = self.file["frames"][name]
                    dataset.resize((self.frames, *dataset.shape[1:]))
                self.file["frames"].attrs[COMPLETE] = self.frames
                for name in set(self.series) - set(self.file["frames"]):  # a series newer than the file: NaN before
                    self._create_series(name, self.frames)
                self._record_resume()
                self._sync()
            except BaseException:
                self.file.close()
                raise
        else:
            self._pending = temporary_file(self.path)
            self.file = h5py.File(self._pending, "w")
            self._create()
        return self

    def _create(self) -> None:
        f = self.file
        for key, value in self.attributes.items():
            f.attrs[key] = value
        f.create_dataset("mesh/triangles", data=self.triangles)
        f.create_dataset("mesh/rest_positions", data=self.rest_positions)
        f.create_dataset("frames/time", shape=(0,), maxshape=(None,), dtype=np.float64, chunks=(256,))
        for name in self.series:
            self._create_series(name, 0)
        self._describe()

    def _create_series(self, name: str, frames: int) -> None:
        shape = self.series[name]
        self.file.create_dataset(f"frames/{name}", shape=(frames, *shape), maxshape=(None, *shape), dtype=np.float64,
                                 chunks=(1, *shape), fillvalue=np.nan)  # fmt: skip

    def _describe(self) -> None:
        """`units` and `description` on every dataset that lacks them (all of a new file's; an older file's)."""
        for group in ("mesh", "frames"):
            for name, dataset in self.file[group].items():
                for key, value in dataset_attributes(f"{group}/{name}").items():
                    if key not in dataset.attrs:
                        dataset.attrs[key] = value

    def _record_resume(self) -> None:
        """A resumed file: the parameters, device and further attributes of this run, its command appended to
        `resumed_by`, and the digests and descriptions an older file lacks; the creation's provenance is kept."""
        f = self.file
        kept = {"scene", "wavewarp_version", "seed", "command_line", "mesh_source", "frames_planned"}
        for key in set(self.attributes) - kept:
            f.attrs[key] = self.attributes[key]
        if "command_line" in self.attributes:
            f.attrs["resumed_by"] = json.dumps([*json.loads(f.attrs.get("resumed_by", "[]")),
                                                self.attributes["command_line"]])
        self._describe()

    def check_resumable(self) -> None:
        """Refuse now (ValueError, the file untouched) what entering would refuse: a resume of another run."""
        with h5py.File(self.path, "r") as f:
            self._check_resumable(f)

    def _check_resumable(self, f) -> None:
        check_same_run(self.path, f, self.attributes)
        for name, shape in self.series.items():
            if f"frames/{name}" in f and f[f"frames/{name}"].shape[1:] != shape:
                raise ValueError(f"cannot resume {self.path!r}: frames/{name} has the shape "
                                 f"{f[f'frames/{name}'].shape[1:]}, this run's is {shape}")  # fmt: skip
        if complete_frames(f) == 0:
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
        self.file["frames"].attrs[COMPLETE] = n
        self._sync()
        self.frames = n
        if self._pending is not None:  # the first frame: the file takes its name
            self.file.close()
            move_into_place(self._pending, self.path)
            self._pending = None
            self.file = h5py.File(self.path, "r+")

    def _sync(self) -> None:
        """Flush HDF5's buffers and the operating system's: the frames so far survive a power cut."""
        self.file.flush()
        os.fsync(self.file.id.get_vfd_handle())

    def set_measurements(self, measured: dict) -> None:
        """Root attributes: `measurements` (JSON) and each numeric measurement by name."""
        self.file.attrs["measurements"] = json.dumps(measured, sort_keys=True)
        for name, value in measured.items():
            if isinstance(value, (bool, int, float)) or (isinstance(value, list) and value and all(
                    isinstance(v, (int, float)) for v in value)):  # fmt: skip
                self.file.attrs[name] = value
        self._sync()

    def __exit__(self, kind, error, trace) -> bool:
        self.file.close()
        if self._pending is not None:  # no frame written: nothing replaces the target
            os.remove(self._pending)
        return False


def check_same_run(path: str, file, run: dict) -> None:
    """ValueError, in one line naming what differs and the fix, unless the open trajectory `file` holds the run
    whose root attributes would be `run` (the scene, version, seed, and the digests of its mesh and rest
    shape, those of the stored arrays)."""
    stored = {**file.attrs, **mesh_digests(file["mesh/triangles"][...], file["mesh/rest_positions"][...])}
    mismatch = resume_mismatch(stored, run)
    if mismatch is not None:
        raise ValueError(f"cannot resume {path!r}: {mismatch}")


def complete_frames(file) -> int:
    """How many frames of an open trajectory are whole (every series written); ValueError where its count
    exceeds what its datasets hold."""
    frames = file["frames"]
    held = min((len(frames[name]) for name in frames), default=0)
    if COMPLETE not in frames.attrs:
        return held  # written before the count existed
    count = int(frames.attrs[COMPLETE])
    if not 0 <= count <= held:
        raise ValueError(f"{file.filename!r} counts {count} complete frames (/frames attribute {COMPLETE}) but its "
                         f"datasets hold {held}: the file was altered or damaged; restore it, or start a new run")
    return count


def stored_run(path) -> dict:
    """A trajectory's root attributes, its `parameters` (parsed) and its complete `frames`; a file that is no
    trajectory (missing, not HDF5, without parameters or frames) is a ValueError naming what it lacks."""
    path = os.fspath(path)
    try:
        with h5py.File(path, "r") as f:
            attributes = dict(f.attrs)
            if "parameters" not in attributes or "scene" not in attributes:
                raise ValueError(f"{path!r} holds no run parameters (root attributes 'scene' and 'parameters'): it "
                                 "is not a wavewarp trajectory")
            if not isinstance(f.get("frames"), h5py.Group) or "time" not in f["frames"]:
                raise ValueError(f"{path!r} holds no frames (/frames/time): it is not a wavewarp trajectory")
            frames = complete_frames(f)
    except OSError as error:
        raise ValueError(f"cannot read {path!r} as an HDF5 trajectory ({error})") from None
    try:
        parameters = json.loads(attributes["parameters"])
    except (TypeError, ValueError):
        raise ValueError(f"{path!r}: its 'parameters' attribute is not JSON: the file is damaged") from None
    return {**attributes, "parameters": parameters, "frames": frames}


def read_frames(path) -> list:
    """The complete frames of a trajectory as (time, frame) pairs, oldest first."""
    with h5py.File(os.fspath(path), "r") as f:
        count = complete_frames(f)
        series = {name: f["frames"][name][:count] for name in f["frames"]}
    times = series.pop("time")
    return [(float(t), {name: values[k] for name, values in series.items()}) for k, t in enumerate(times)]


def stored_parameters(path) -> dict:
    """The parameters a trajectory's run used (its `parameters` attribute)."""
    return stored_run(path)["parameters"]


def last_frame(path) -> dict:
    """The last frame of a trajectory as {"time": t, name: array, ...} plus "frames" (the count)."""
    with h5py.File(os.fspath(path), "r") as f:
        frames = f["frames"]
        count = complete_frames(f)
        if count == 0:
            raise ValueError(f"{os.fspath(path)!r} has no frames to resume from")
        out = {name: frames[name][count - 1] for name in frames}
        out["time"] = float(out["time"])
        out["frames"] = count
        return out
