"""USD animation output (docs/theory/scenes.md): Z up, Loop subdivision scheme, time-sampled points and field.

Viewers draw the same Loop limit surface the simulation uses, because the control mesh is
authored with `subdivisionScheme = "loop"`. The file is written to a temporary sibling and
renamed when complete; an interrupted run (Ctrl-C) still keeps the frames written so far.
"""

from __future__ import annotations

import os

import numpy as np
from matplotlib import colormaps

from .io import atomic_path

def colour_map(values, low: float, high: float, name: str = "viridis") -> np.ndarray:
    """(n, 3) RGB colours of `values` scaled from [low, high] by matplotlib's colormap `name`."""
    s = np.clip((np.asarray(values, dtype=np.float64) - low) / max(high - low, 1e-300), 0.0, 1.0)
    return colormaps[name](s)[:, :3]


class UsdAnimation:
    """Context manager writing `/World/Shell` frame by frame.

    `field_name` names the per-vertex scalar (e.g. "concentration"); `field_range` fixes the
    colour scale. `ground_size` > 0 adds `/World/Ground`, a square at z = 0.
    """

    def __init__(self, path, triangles, *, fps: float = 24.0, field_name: str = "concentration",
                 field_range=(0.0, 1.0), ground_size: float = 0.0):  # fmt: skip
        suffix = os.path.splitext(os.fspath(path))[1]
        if suffix not in (".usd", ".usda", ".usdc"):
            raise ValueError(f"USD output {os.fspath(path)!r} must end in .usd, .usda or .usdc")
        self.path = path
        self.triangles = np.asarray(triangles, dtype=np.int32)
        self.fps = float(fps)
        self.field_name = field_name
        self.field_range = tuple(float(v) for v in field_range)
        self.ground_size = float(ground_size)
        self.frames = 0

    def __enter__(self) -> UsdAnimation:
        from pxr import Sdf, Usd, UsdGeom, Vt

        self._atomic = atomic_path(self.path)
        self._tmp = self._atomic.__enter__()
        self.stage = Usd.Stage.CreateNew(self._tmp)
        UsdGeom.SetStageUpAxis(self.stage, UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(self.stage, 1.0)
        self.stage.SetTimeCodesPerSecond(self.fps)
        world = UsdGeom.Xform.Define(self.stage, "/World")
        self.stage.SetDefaultPrim(world.GetPrim())
        self.mesh = UsdGeom.Mesh.Define(self.stage, "/World/Shell")
        self.mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.loop)
        self.mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(self.triangles)))
        self.mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(self.triangles.reshape(-1).tolist()))
        self.mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
        self.points = self.mesh.CreatePointsAttr()
        self.extent = self.mesh.CreateExtentAttr()
        api = UsdGeom.PrimvarsAPI(self.mesh)
        self.colour = api.CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex)
        self.field = api.CreatePrimvar(self.field_name, Sdf.ValueTypeNames.FloatArray, UsdGeom.Tokens.vertex)
        if self.ground_size > 0:
            self._add_ground()
        return self

    def _add_ground(self) -> None:
        from pxr import Gf, UsdGeom, Vt

        g = 0.5 * self.ground_size
        ground = UsdGeom.Mesh.Define(self.stage, "/World/Ground")
        ground.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(x, y, 0.0) for x, y in ((-g, -g), (g, -g), (g, g), (-g, g))]))
        ground.CreateFaceVertexCountsAttr(Vt.IntArray([4]))
        ground.CreateFaceVertexIndicesAttr(Vt.IntArray([0, 1, 2, 3]))
        ground.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        ground.CreateDisplayColorAttr(Vt.Vec3fArray([Gf.Vec3f(0.6, 0.6, 0.6)]))

    def add_frame(self, time: float, frame: dict) -> None:
        """Author one frame (the writers' protocol): `frame["positions"]`, control points (V, 3), and
        `frame[field_name]`, the per-vertex field (V,; zeros when absent). The time code is the frame's
        index (`fps` per second); `time` is the simulated time."""
        from pxr import Vt

        del time  # the time code counts frames
        points = np.asarray(frame["positions"], dtype=np.float64)
        field = frame.get(self.field_name)
        if not np.all(np.isfinite(points)):
            raise ValueError("refusing to write a frame with non-finite positions")
        t = float(self.frames)
        self.points.Set(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)), t)
        self.extent.Set(Vt.Vec3fArray.FromNumpy(np.stack([points.min(0), points.max(0)]).astype(np.float32)), t)
        values = np.zeros(len(points)) if field is None else np.asarray(field, dtype=np.float64)
        self.field.Set(Vt.FloatArray.FromNumpy(values.astype(np.float32)), t)
        self.colour.Set(Vt.Vec3fArray.FromNumpy(colour_map(values, *self.field_range).astype(np.float32)), t)
        if self.frames == 0:
            self.stage.SetStartTimeCode(t)
        self.stage.SetEndTimeCode(t)
        self.frames += 1

    def __exit__(self, kind, error, trace) -> bool:
        keep = kind is None or (issubclass(kind, KeyboardInterrupt) and self.frames > 0)
        if keep:
            self.stage.GetRootLayer().Save()
        del self.stage
        if keep:
            self._atomic.__exit__(None, None, None)  # rename into place
        else:
            self._atomic.__exit__(kind, error, trace)  # remove the temporary file
        return False
