"""XDMF frames for ParaView: the limit surface with per-frame concentration and displacement.

meshio's time-series writer stores the mesh once (the rest limit points), so motion is the point
field `displacement` (limit points minus rest limit points; ParaView: "Warp By Vector"), next to
`concentration` (the field's values at the limit points). It writes FILE.xdmf and its FILE.h5;
both go to a hidden temporary folder beside the target and are moved into place when the writer
closes, also after Ctrl-C (frames so far kept); any other error leaves nothing.
"""

from __future__ import annotations

import os
import shutil
import tempfile

import numpy as np

from .io import check_writable, remove_stale_temporaries, temporary_prefix


class XdmfWriter:
    """Context manager: `add_frame(time, frame)` per frame (the writers' protocol), with
    `limit_points(x)` and `field_values(c)` turning the frame's control positions and concentrations
    into the limit surface's points and the field's values there."""

    def __init__(self, path, *, triangles, rest_points, limit_points, field_values):
        if os.path.splitext(os.fspath(path))[1] != ".xdmf":
            raise ValueError(f"XDMF output {os.fspath(path)!r} must end in .xdmf")
        self.path = os.path.abspath(os.fspath(path))
        self.triangles = np.asarray(triangles, dtype=np.int64)
        self.rest_points = np.asarray(rest_points, dtype=np.float64)
        self.limit_points, self.field_values = limit_points, field_values
        self.frames = 0

    def __enter__(self) -> XdmfWriter:
        import meshio

        check_writable(self.path)
        remove_stale_temporaries(self.path)
        prefix = temporary_prefix(self.path)
        self._folder = tempfile.mkdtemp(prefix=os.path.basename(prefix), dir=os.path.dirname(prefix))
        name = os.path.basename(self.path)
        self._writer = meshio.xdmf.TimeSeriesWriter(os.path.join(self._folder, name))
        cwd = os.getcwd()
        os.chdir(self._folder)  # meshio opens its data file (STEM.h5) relative to the working directory
        try:
            self._writer.__enter__()
        finally:
            os.chdir(cwd)
        self._writer.write_points_cells(self.rest_points, [("triangle", self.triangles)])
        return self

    def add_frame(self, time: float, frame: dict) -> None:
        limit_points = np.asarray(self.limit_points(frame["positions"]), dtype=np.float64)
        concentration = np.asarray(self.field_values(frame["concentration"]), dtype=np.float64)
        if not (np.all(np.isfinite(limit_points)) and np.all(np.isfinite(concentration))):
            raise ValueError("refusing to write a frame with non-finite values")
        self._writer.write_data(float(time), point_data={"concentration": concentration,
                                                         "displacement": limit_points - self.rest_points})  # fmt: skip
        self.frames += 1

    def __exit__(self, kind, error, trace) -> bool:
        self._writer.__exit__(None, None, None)
        keep = kind is None or (issubclass(kind, KeyboardInterrupt) and self.frames > 0)
        if keep:
            stem = os.path.splitext(os.path.basename(self.path))[0]
            for name in sorted(os.listdir(self._folder), key=lambda n: n.endswith(".xdmf")):  # data first
                target = os.path.join(os.path.dirname(self.path), name)
                if not (name.endswith(".xdmf") or name.startswith(stem)):
                    continue
                os.replace(os.path.join(self._folder, name), target)
        shutil.rmtree(self._folder, ignore_errors=True)
        return False
