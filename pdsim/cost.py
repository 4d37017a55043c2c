"""What a run will cost, estimated before anything is allocated: time per frame, total time, the render surfaces'
memory and the cache's size, from counts and a calibration measured on this machine class.

The counts are the pre-flight's (pdsim/preflight.py): per body its points, its bonds (peridynamics: the interior
count per particle, an upper bound) or links (lattice), its elements (FEM), its steps per frame, and its render
surface's vertices at rest (the input surface refined to edges of one spacing, as pdsim.fragment_surfaces builds it;
an FEM body's boundary vertices; lattices write points only). A calibration per device kind
(``cost_calibration_cpu.json``, ``cost_calibration_cuda.json`` beside this module, written by ``python
tools/preflight_calibration.py --cost --device KIND --write`` on that kind of machine) holds the machine, date, command
and load average it was measured with and:

- ``step_seconds``: wall time of one step: a constant per step (the launches) of each method, and per estimated bond
  visit (elastic, with fracture, with plasticity) and per particle (peridynamics), per element (elastic, with
  fracture) and per vertex (explicit FEM), per lattice point and per link (lattice); and the contact between FEM
  surfaces (pdsim.contact.MethodContact, working at rest on explicit FEM bodies beside another FEM body): a
  constant per step and per boundary vertex of such a body (``fem_contact_step``, ``fem_contact_vertex``); a
  lattice that can lose links: a constant per step and per link more (``lattice_fracture_step``,
  ``lattice_fracture_link``: the link-loss pass); boundary conditions on a peridynamic or FEM solver's bodies: a
  constant per step of that solver (``conditions_step``: the conditions' state and the work of the supports). A
  calibration measured before one of these terms (:data:`LATER_TERMS`; the CUDA one of 2026-12-04 lacks them all)
  leaves that cost out. The blocks measured spin, as a body in a shot moves: every frame writes new positions, and
  every FEM step turns each element's corotated frame (one Newton step of the polar rotation), which a body at rest
  would skip;
- ``frame_seconds``: per frame outside the steps (views, render surfaces, the USD writer): a constant, per point of
  each method and per surface vertex;
- ``build_seconds``: building the solvers, per point, per estimated bond and per element, plus a constant;
- ``cache_bytes``: cache bytes per frame, per point of each method and per surface vertex, plus a constant;
- ``memory_bytes``: peak host memory per surface vertex (the render surfaces and their views).

A run on a device kind with no calibration gets the CPU's figures and says so (``calibrated`` False). The implicit and
static FEM solves have no step calibration: their time is left out (``seconds_per_frame`` None).
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

from .fem.model import _mean_edge_length
from .fragment_surfaces.booleans import refine_surface

DEVICE_KINDS = ("cpu", "cuda")  # the device kinds a calibration can be measured on
HOUR = 3600.0  # a run estimated to take longer than this [s] is warned about
FEM_CONTACT_TERMS = ("fem_contact_step", "fem_contact_vertex")  # the contact between FEM surfaces
LATTICE_FRACTURE_TERMS = ("lattice_fracture_step", "lattice_fracture_link")  # a lattice's link-loss pass
CONDITIONS_TERM = "conditions_step"  # the boundary conditions of a peridynamic or FEM solver, per step
LATER_TERMS = (*FEM_CONTACT_TERMS, *LATTICE_FRACTURE_TERMS, CONDITIONS_TERM)
"""Step constants added to the model after the first calibrations: a calibration measured before one (the CUDA one of
2026-12-04 lacks them all) counts it as 0, and its estimates leave that cost out."""
PD_FEATURES = ("elastic", "fracture", "plastic")  # the peridynamic step's calibrated variants
FEM_FEATURES = ("elastic", "fracture")  # the explicit FEM step's calibrated variants


def device_kind(device) -> str:
    """'cpu' or 'cuda' of a Warp device name such as 'cuda:0'."""
    return str(device).split(":")[0]


def calibration_file(kind: str) -> str:
    """The calibration file of device kind ``kind`` ('cpu' or 'cuda') beside this module."""
    return os.path.join(os.path.dirname(os.path.abspath(__file__)), f"cost_calibration_{kind}.json")


def _load_calibrations() -> dict:
    out = {}
    for kind in DEVICE_KINDS:
        if os.path.exists(calibration_file(kind)):
            with open(calibration_file(kind), encoding="utf-8") as f:
                out[kind] = json.load(f)
    return out


CALIBRATIONS = _load_calibrations()  # device kind -> calibration, for the kinds measured
CALIBRATION = CALIBRATIONS["cpu"]  # the CPU's: the figures given on a kind with none of its own


def calibration_for(device) -> dict:
    """The calibration of ``device``'s kind, or the CPU's where that kind has none."""
    return CALIBRATIONS.get(device_kind(device), CALIBRATION)


def _method(body) -> str:
    return getattr(type(body), "method", "")


def fem_edge_length(mesh) -> float:
    """An FEM mesh's edge length [m] estimated from its volume per element (a regular tetrahedron's edge)."""
    return float((abs(mesh.volume) / max(mesh.element_count, 1) * 6.0 * math.sqrt(2.0)) ** (1.0 / 3.0))


def _refined_vertices(shape, spacing: float) -> int:
    """Vertices of ``shape``'s surface refined to edges of about ``spacing`` [m] (pdsim.fragment_surfaces' input
    surface: the render surface of an intact body)."""
    return len(refine_surface(shape.vertices, shape.faces, float(spacing))[0])


def surface_vertices(body) -> float:
    """Vertex count of a body's render surface at rest (the surface a frame without fracture writes): peridynamics:
    the input shape refined to the spacing; FEM: the input surface refined to the mean edge length (smooth crack
    surfaces) or the mesh's boundary vertices, plus an embedded render mesh's; 0 for the lattice (points only).
    Fragments add vertices along their cracks."""
    method = _method(body)
    if method == "peridynamics":
        return float(_refined_vertices(body.shape, body.spacing))
    if method == "fem":
        mesh = body.mesh
        if getattr(body, "surface_shape", None) is not None:
            n = _refined_vertices(body.surface_shape, _mean_edge_length(mesh.vertices, mesh.tets))
        else:
            n = int(np.unique(mesh.boundary_faces()).size)
        render = getattr(body, "render_mesh", None)
        if render is not None:
            n += len(render.vertices)
        return float(n)
    return 0.0


def body_counts(body, bonds_per_particle) -> dict:
    """The counts a body's cost is estimated from: method, points, bonds (estimated: points x
    ``bonds_per_particle(body)``) or links, elements, surface_vertices, steps (lattice steps per frame; None: the
    scene's substeps), features ("plastic": a peridynamic body with a yield stress; else "fracture" when bonds or
    elements can break; else "elastic"), calibrated (False: no
    step calibration for this body, e.g. an implicit FEM body), contact_vertices (an explicit FEM body's boundary
    vertices, which the contact between FEM surfaces works on: :func:`fem_surface_contact`), breaks (its bonds,
    elements or links can break), conditions (its boundary conditions; a lattice's grips are its own kinds, 0)."""
    method = _method(body)
    out = {"method": method, "points": 0, "bonds": 0.0, "elements": 0, "surface_vertices": surface_vertices(body),
           "steps": None, "features": "elastic", "calibrated": True, "contact_vertices": 0,
           "breaks": bool(getattr(body, "fractures", False)),
           "conditions": len(getattr(body, "conditions", ()))}  # fmt: skip
    if method == "peridynamics":
        n = int(body.particle_count)
        out.update(points=n, bonds=n * float(bonds_per_particle(body)))
        if getattr(body.material, "yield_stress", None) is not None:
            out["features"] = "plastic"
        elif body.fractures:
            out["features"] = "fracture"
    elif method == "fem":
        out.update(points=int(body.vertex_count), elements=int(body.element_count))
        if getattr(body, "fractures", False):
            out["features"] = "fracture"
        out["calibrated"] = getattr(body, "integrator", "explicit") == "explicit"
        out["contact_vertices"] = int(np.unique(body.mesh.boundary_faces()).size) if out["calibrated"] else 0
    else:
        out.update(points=int(getattr(body, "particle_count", 0)), bonds=float(getattr(body, "link_count", 0)))
        out["steps"] = int(getattr(body, "steps_per_frame", 1))
        if getattr(body, "fracture", None) is not None:
            out.update(features="fracture", breaks=True)
    return out


def fem_surface_contact(bodies: list[dict]) -> list[bool]:
    """Per body of ``bodies`` (body_counts), whether the contact between FEM surfaces works on it each step at rest:
    every explicit FEM body where there are several (pdsim/run.py, ``method_contact``; a scene with contact switched
    off is counted as with it on). A body that can crack, alone, is one piece at rest, and the contact searches
    nothing until it cracks (pdsim/surface_contact.py): like its surface rebuilds, that is left out."""
    explicit = [b["method"] == "fem" and b["calibrated"] for b in bodies]
    several = sum(explicit) > 1
    return [e and several for e in explicit]


def step_seconds(counts: dict, calibration: dict = CALIBRATION, surface_contact: bool = False) -> float:
    """Wall time of one step of a body [s] (a lattice step for the lattice); ``surface_contact``: the contact
    between FEM surfaces works on this FEM body (:func:`fem_surface_contact`)."""
    c = calibration["step_seconds"]
    method = counts["method"]
    if method == "peridynamics":
        per_bond = c[f"pd_bond_{counts['features']}"]
        return c["pd_step"] + counts["bonds"] * per_bond + counts["points"] * c["pd_particle"]
    if method == "fem":
        per_element = c[f"fem_element_{counts['features']}"]
        seconds = c["fem_step"] + counts["elements"] * per_element + counts["points"] * c["fem_vertex"]
        if surface_contact:
            per_step, per_vertex = (c.get(term, 0.0) for term in FEM_CONTACT_TERMS)
            seconds += per_step + counts["contact_vertices"] * per_vertex
        return seconds
    seconds = c["lattice_step"] + counts["points"] * c["lattice_point"] + counts["bonds"] * c["lattice_link"]
    if counts["features"] == "fracture":
        per_step, per_link = (c.get(term, 0.0) for term in LATTICE_FRACTURE_TERMS)
        seconds += per_step + counts["bonds"] * per_link
    return seconds


def conditions_seconds(bodies: list[dict], calibration: dict = CALIBRATION) -> float:
    """Wall time per scene step [s] of the boundary conditions: ``conditions_step`` once for each solver (the
    peridynamic one, the explicit FEM one) with a body that has a boundary condition."""
    per_step = calibration["step_seconds"].get(CONDITIONS_TERM, 0.0)
    held = {b["method"] for b in bodies if b.get("conditions", 0) and b["method"] in ("peridynamics", "fem")}
    return per_step * len(held)


def estimate_cost(bodies: list[dict], *, substeps: int, frames: int, device: str,
                  calibration: dict | None = None) -> dict:  # fmt: skip
    """The cost of a run of ``frames`` frames of ``substeps`` steps of bodies with counts ``bodies`` (body_counts).

    Returns plain JSON values: seconds_per_frame, build_seconds and total_seconds [s] (None where a body has no step
    calibration; the bodies at rest: the render-surface rebuilds of the frames where a body breaks are left out, and
    ``rebuilds_left_out`` says whether a body with a render surface can break), surface_vertices (at rest),
    surface_bytes (host memory of the render surfaces [B]), cache_bytes (the cache, frames 0..frames [B]), calibrated
    (False off the calibration's device: the CPU figures are given), device, and the calibration's machine, date
    and command. ``calibration``: None takes ``device``'s (:func:`calibration_for`)."""
    if calibration is None:
        calibration = calibration_for(device)
    fs, bs, cb = calibration["frame_seconds"], calibration["build_seconds"], calibration["cache_bytes"]
    vertices = float(sum(b["surface_vertices"] for b in bodies))
    step = 0.0
    timed = all(b["calibrated"] for b in bodies)
    for b, contact in zip(bodies, fem_surface_contact(bodies)):
        step += step_seconds(b, calibration, contact) * (substeps if b["steps"] is None else b["steps"])
    step += conditions_seconds([b for b in bodies if b["calibrated"]], calibration) * substeps
    points = {m: sum(b["points"] for b in bodies if b["method"] == m) for m in ("peridynamics", "fem", "lattice")}
    per_frame = step + fs["constant"] + vertices * fs["surface_vertex"]
    per_frame += sum(points[m] * fs["point"][m] for m in points)
    build = bs["constant"] + sum(points.values()) * bs["point"]
    build += sum(b["bonds"] for b in bodies) * bs["bond"] + sum(b["elements"] for b in bodies) * bs["element"]
    cache_frame = cb["frame"] + vertices * cb["surface_vertex"] + sum(points[m] * cb["point"][m] for m in points)
    on_device = device_kind(device) == calibration["device"]
    return {
        "seconds_per_frame": per_frame if timed else None,
        "build_seconds": build if timed else None,
        "total_seconds": build + frames * per_frame if timed else None,
        "surface_vertices": vertices,
        "rebuilds_left_out": any(b.get("breaks", False) and b["surface_vertices"] > 0 for b in bodies),
        "surface_bytes": vertices * calibration["memory_bytes"]["surface_vertex"],
        "cache_bytes": (frames + 1) * cache_frame,
        "calibrated": on_device,
        "device": str(device),
        "calibration": {k: calibration[k] for k in ("machine", "date", "command", "device")},
    }


def format_seconds(seconds: float) -> str:
    """A duration for messages: 0.42 s, 37 s, 12 min, 5.3 h."""
    if seconds < 10.0:
        return f"{seconds:.2g} s"
    if seconds < 120.0:
        return f"{seconds:.0f} s"
    if seconds < 2.0 * HOUR:
        return f"{seconds / 60.0:.0f} min"
    return f"{seconds / HOUR:.1f} h"
