"""What each dataset of an HDF5 trajectory holds: its units and a one-line description (the `units` and
`description` attributes of every dataset, docs/theory/scenes.md "Outputs").

Lengths and times are the scene's nondimensional units (the root attribute `time_unit` names the
time's); "1" marks a dimensionless quantity or an index.
"""

from __future__ import annotations

COUNTER = "count_"  # the prefix of the frames' bookkeeping series (relaxations, iterations, ...)

DATASETS = {
    "mesh/triangles": ("1", "control triangles: 0-based vertex indices, counter-clockwise seen from outside"),
    "mesh/rest_positions": ("length", "control vertices of the rest shape (refined and seeded as the run used them)"),
    "frames/time": ("time", "simulated time of each frame"),
    "frames/positions": ("length", "control-vertex positions x of each frame (the limit surface's control points)"),
    "frames/velocities": ("length/time", "control-vertex velocities v of each frame"),
    "frames/concentration": ("1", "control values of the active chemical c of each frame"),
    "frames/concentration_rate": ("1/time", "control values of the telegraph wave's rate dc/dt of each frame"),
    "frames/inhibitor": ("1", "control values of the FitzHugh-Nagumo inhibitor w of each frame"),
    "frames/reaction_amount": ("length^2", "amount the reaction has added to C = integral of c over the surface"),
    "frames/reaction_per_vertex": ("length^2", "each control vertex's share of reaction_amount"),
    "frames/first_arrival": ("time", "each vertex's first-front arrival time (-1: not yet; 0: at t = 0)"),
    "frames/trace": ("time, 1, length", "per chemistry step up to the frame: t, c at the origin vertex, the centre "
                     "of mass (3), the origin vertex's position (3)"),
    "frames/chemistry_dt": ("time", "the chemistry time step the frame's dc/dt belongs to (adaptive step)"),
    "frames/relaxation_count": ("1", "relaxations since the previous frame (the slots used below)"),
    "frames/relaxation_times": ("time", "times of the relaxations since the previous frame (0 in unused slots)"),
    "frames/relaxation_concentration": ("1", "control concentrations at those relaxations (the arrival times' "
                                        "samples; 0 in unused slots)"),
}


def dataset_attributes(name: str) -> dict:
    """{"units", "description"} of the dataset `name` ("frames/positions"); a scene's own series without an
    entry is described by its name."""
    if name in DATASETS:
        units, description = DATASETS[name]
    elif name.startswith(f"frames/{COUNTER}"):
        units, description = "1", f"running count of {name[len('frames/' + COUNTER):]} (bookkeeping for a resume)"
    else:
        units, description = "scene units", f"the scene's per-frame series {name.rpartition('/')[2]}"
    return {"units": units, "description": description}
