"""USD animation output (docs/theory/scenes.md): Z up, time-sampled points and field, one colour scale per run.

Surface: with `surface="loop"` the control mesh is authored with `subdivisionScheme = "loop"`, so viewers
draw the same Loop limit surface the simulation uses. With `surface="baked"` the mesh is the control mesh
refined `bake_levels` times by Loop subdivision with every vertex placed on the limit surface, and the
field likewise at its limit values (`subdivisionScheme = "none"`), for viewers and renderers that do not
subdivide.

Time: time codes count frames (frame k at time code k, `fps` per second), so viewers play at a steady,
sensible speed whatever the simulated time step. The simulated time of frame k is the value of the
time-sampled attribute `/World.wavewarp:time` at time code k, and the root layer's customLayerData holds
all of them (`wavewarp:time`, in the order of the time codes) with their unit (`wavewarp:timeUnit`).

Colours: `displayColor` is the colour map of the field on one scale for the whole run, authored when the
file closes: the run's own range (`colours.run_range` of every frame's field) unless an explicit
`field_range` is given. customLayerData states the scale (`wavewarp:colourRange`, `wavewarp:colourField`,
`wavewarp:colourMap`, and `wavewarp:colourPercentiles` for the run's range).

The file is written to a temporary sibling and renamed when complete; an interrupted run (Ctrl-C) still
keeps the frames written so far, coloured on the range of those frames.
"""

from __future__ import annotations

import os

import numpy as np

from .checks import count
from .colours import COLOUR_MAP, PERCENTILES, colour_map, run_range
from .io import atomic_path
from .refinement import BakedSurface
from .sizing import check_bake_size

SURFACES = ("loop", "baked")
TIME_UNIT = "the scene's time unit (docs/theory/scenes.md)"


class UsdAnimation:
    """Context manager writing `/World/Shell` frame by frame.

    `field_name` names the per-vertex scalar (e.g. "concentration"); `field_range` (low, high) fixes the
    colour scale, None (default) takes the run's own range. `surface` is "loop" (the control mesh, Loop
    subdivision scheme) or "baked" (refined `bake_levels` ≥ 1 times onto the limit surface).
    `ground_size` > 0 adds `/World/Ground`, a square at z = 0.
    """

    def __init__(self, path, triangles, *, fps: float = 24.0, field_name: str = "concentration", field_range=None,
                 surface: str = "loop", bake_levels: int = 2, ground_size: float = 0.0):  # fmt: skip
        suffix = os.path.splitext(os.fspath(path))[1]
        if suffix not in (".usd", ".usda", ".usdc"):
            raise ValueError(f"USD output {os.fspath(path)!r} must end in .usd, .usda or .usdc")
        if surface not in SURFACES:
            raise ValueError(f"--usd-surface must be loop or baked, got {surface!r}")
        levels = count("--usd-bake-levels", bake_levels, 1)
        self.path = path
        self.fps = float(fps)
        self.field_name = field_name
        self.field_range = None if field_range is None else tuple(float(v) for v in field_range)
        self.ground_size = float(ground_size)
        if surface == "baked":
            check_bake_size(len(triangles), levels)  # before the refined surface is built
        self.baked = BakedSurface(triangles, levels) if surface == "baked" else None
        self.triangles = np.asarray(triangles if self.baked is None else self.baked.triangles, dtype=np.int32)
        self.frames = 0
        self.times: list[float] = []
        self.fields: list[np.ndarray] = []  # each frame's field as the file holds it (float32), coloured at close

    @property
    def points_per_frame(self) -> int:
        """Points authored per frame: the control vertices, or the baked surface's."""
        return int(self.triangles.max()) + 1

    @property
    def surface_label(self) -> str:
        """`wavewarp:surface` in the file: "loop", "baked 1 level" or "baked k levels"."""
        if self.baked is None:
            return "loop"
        return f"baked {self.baked.levels} level" + ("s" if self.baked.levels > 1 else "")

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
        self.time_attribute = world.GetPrim().CreateAttribute("wavewarp:time", Sdf.ValueTypeNames.Double, custom=True)
        self.mesh = UsdGeom.Mesh.Define(self.stage, "/World/Shell")
        self.mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.loop if self.baked is None else UsdGeom.Tokens.none)
        self.mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(self.triangles)))
        self.mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(self.triangles.reshape(-1)))
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
        `frame[field_name]`, the per-vertex field's control values (V,; zeros when absent). The time code
        is the frame's index (`fps` per second); `time`, the simulated time, goes to `/World.wavewarp:time`."""
        from pxr import Vt

        points = np.asarray(frame["positions"], dtype=np.float64)
        field = frame.get(self.field_name)
        if not np.all(np.isfinite(points)):
            raise ValueError("refusing to write a frame with non-finite positions")
        values = np.zeros(len(points)) if field is None else np.asarray(field, dtype=np.float64)
        if self.baked is not None:
            points, values = self.baked.values(points), self.baked.values(values)
        code = float(self.frames)
        self.points.Set(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)), code)
        self.extent.Set(Vt.Vec3fArray.FromNumpy(np.stack([points.min(0), points.max(0)]).astype(np.float32)), code)
        authored = values.astype(np.float32)
        self.field.Set(Vt.FloatArray.FromNumpy(authored), code)
        self.time_attribute.Set(float(time), code)
        if self.frames == 0:
            self.stage.SetStartTimeCode(code)
        self.stage.SetEndTimeCode(code)
        self.fields.append(authored)
        self.times.append(float(time))
        self.frames += 1

    def _author_colours(self) -> None:
        """displayColor of every frame on the run's one scale, and the scale and times in customLayerData."""
        from pxr import Sdf, Vt

        low, high = run_range(self.fields) if self.field_range is None else self.field_range
        for code, values in enumerate(self.fields):
            self.colour.Set(Vt.Vec3fArray.FromNumpy(colour_map(values, low, high).astype(np.float32)), float(code))
        stated = self.mesh.GetPrim().CreateAttribute("wavewarp:colourRange", Sdf.ValueTypeNames.Double2, custom=True)
        stated.Set((low, high))
        layer = self.stage.GetRootLayer()
        data = dict(layer.customLayerData)
        data.update({"wavewarp:time": Vt.DoubleArray(self.times), "wavewarp:timeUnit": TIME_UNIT,
                     "wavewarp:surface": self.surface_label, "wavewarp:colourField": self.field_name,
                     "wavewarp:colourMap": COLOUR_MAP,
                     "wavewarp:colourRange": Vt.DoubleArray([low, high])})  # fmt: skip
        if self.field_range is None:
            data["wavewarp:colourPercentiles"] = Vt.DoubleArray(PERCENTILES)
        layer.customLayerData = data

    def __exit__(self, kind, error, trace) -> bool:
        keep = kind is None or (issubclass(kind, KeyboardInterrupt) and self.frames > 0)
        if keep:
            self._author_colours()
            self.stage.GetRootLayer().Save()
        del self.stage
        if keep:
            self._atomic.__exit__(None, None, None)  # rename into place
        else:
            self._atomic.__exit__(kind, error, trace)  # remove the temporary file
        return False
