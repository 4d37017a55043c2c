"""The catalogue of bad inputs: each case builds one mistake (through the scene API or the ``pdsim`` command line),
and the one-line message users see for it. ``tests/test_errors_catalogue.py`` runs every case (error type, message,
one line, nothing half-written: no cache created, an earlier cache left as it was); this script runs them too and
writes docs/errors.md from the same list, so the page and the tests cannot drift apart.

    python tools/errors_catalogue.py            # rewrites docs/errors.md
    python tools/errors_catalogue.py --check    # exit 1 when docs/errors.md is out of date

Run cases call :func:`pdsim.preflight.preflight` with the output path, time step and frame count before
``Scene.run``, as the run (pdsim.run.run_scene) does itself.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import hashlib
import importlib.util
import os
import re
import subprocess
import sys
import tempfile
import textwrap
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh
import warp as wp

import pdsim
import pdsim.fem.mesh
import pdsim.checkpoint
import pdsim.memory
import pdsim.output.usd_stream
from pdsim.output.usd_files import CacheError
import pdsim.preflight
from pdsim.lattice import Lattice, LatticeBody

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "errors.md"
MAT = {"density": 1000.0, "youngs_modulus": 1.0e5, "poisson_ratio": 0.3}


class NoError(AssertionError):
    """A case that raised nothing (or a command that exited 0)."""


# ------------------------------------------------------------------------------------------------------- workspace
class Workspace:
    """A case's folder: inputs it writes (allowed to stay), earlier outputs it plants (must stay byte for byte) and
    the output path of its run. After the case, anything else in the folder was written by the failed run."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.inputs: set[Path] = set()
        self.earlier: dict[Path, str] = {}

    def input(self, name: str, content: str | bytes) -> Path:
        path = self.root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content)
        self.inputs.add(path)
        return path

    def folder(self, name: str) -> Path:
        path = self.root / name
        path.mkdir(parents=True, exist_ok=True)
        self.inputs.add(path)
        return path

    def earlier_cache(self, name: str = "out.usdc") -> Path:
        """An earlier cache at ``name`` (a small USD text layer) that the failed run must leave as it was."""
        path = self.root / name
        path.write_text('#usda 1.0\n(\n    doc = "an earlier pdsim cache"\n)\n\ndef Xform "World"\n{\n}\n')
        self.earlier[path] = hashlib.sha256(path.read_bytes()).hexdigest()
        return path

    @property
    def out(self) -> Path:
        return self.root / "out.usdc"

    def leftovers(self) -> list[str]:
        """Files and folders in the workspace that the case did not plant (written by the failed run), and earlier
        outputs that changed."""
        found = []
        for p in sorted(self.root.rglob("*")):
            if p in self.inputs or any(q in p.parents for q in self.inputs if q.is_dir()):
                continue
            if p in self.earlier:
                if hashlib.sha256(p.read_bytes()).hexdigest() != self.earlier[p]:
                    found.append(f"{p.name} (earlier output changed)")
                continue
            found.append(str(p.relative_to(self.root)))
        found += [f"{p.name} (earlier output removed)" for p in self.earlier if not p.exists()]
        return found


# ----------------------------------------------------------------------------------------------------------- cases
@dataclass
class Case:
    """One bad input. ``act(ws)`` makes the mistake: a scene-API case raises, a command-line case returns the
    CompletedProcess of ``pdsim``. ``fragments`` must appear in the message."""

    id: str
    area: str
    wrong: str
    allowed: str
    error: type
    fragments: tuple
    act: Callable
    cli: bool = False
    exit_code: int = 1  # the command line's exit status (2: an exception of the scene script)
    keeps_frames: bool = False  # a failure during the run: the cache of the finished frames stays at ws.out
    needs_ftetwild: bool = False
    skip_with_cuda: bool = False
    notes: list = field(default_factory=list)


CASES: list[Case] = []


def case(id, area, wrong, allowed, error, *fragments, **kwargs):
    def register(fn):
        CASES.append(Case(id, area, wrong, allowed, error, fragments, fn, **kwargs))
        return fn

    return register


def _material(**overrides):
    return pdsim.Material(**{**MAT, **overrides})


def _scene(**kwargs) -> pdsim.Scene:
    return pdsim.Scene(fps=100.0, frames=2, **kwargs)


def _beam(scene, name="beam", center=(0.15, 0.0, 0.5), spacing=0.05):
    return scene.add_peridynamic_body(pdsim.box((0.3, 0.1, 0.1), center=center), _material(), spacing, name=name)


def _run(scene, ws: Workspace, out=None, *, dt=None, frames=None, **kwargs):
    """What Scene.run does with the pre-flight: the checks, then the run (CPU, quiet)."""
    out = ws.out if out is None else out
    pdsim.preflight.preflight(scene, device="cpu", out=out, dt=dt, frames=frames)
    scene.run(out, device="cpu", dt=dt, frames=frames, progress=False, **kwargs)


@contextlib.contextmanager
def _patched(module, name, value):
    old = getattr(module, name)
    setattr(module, name, value)
    try:
        yield
    finally:
        setattr(module, name, old)


@contextlib.contextmanager
def _free_memory(host_bytes: float):
    """``host_bytes`` of free host memory and no CUDA device, for messages that do not depend on the machine."""
    with (
        _patched(pdsim.memory, "free_host_memory", lambda: host_bytes),
        _patched(pdsim.preflight, "_free_cuda_memory", list),
    ):
        yield


def _box_mesh_text(extents=(0.3, 0.2, 0.1), *, open_faces=0, scale=1.0) -> str:
    m = trimesh.creation.box(extents=np.asarray(extents) * scale)
    faces = m.faces[: len(m.faces) - open_faces]
    return trimesh.exchange.obj.export_obj(trimesh.Trimesh(m.vertices, faces, process=False))


def _sliver_mesh():
    """A structured box mesh plus one sliver (quality about 3e-3) glued on a boundary face: vertices, tets."""
    m = pdsim.box_tet_mesh((0.4, 0.2, 0.2), (8, 4, 4))
    f = m.boundary_faces()[0]
    x = m.vertices[f]
    n = np.cross(x[1] - x[0], x[2] - x[0])
    n /= np.linalg.norm(n)
    v = np.vstack([m.vertices, x.mean(axis=0) + 1.0e-4 * n])
    t = np.vstack([m.tets, [[f[0], f[1], f[2], len(m.vertices)]]])
    return v, t


# -- meshes and shapes ------------------------------------------------------------------------------------------
A_MESH = "meshes and shapes"


@case("flat_mesh", A_MESH, "an OBJ of a flat open sheet (a square of two triangles)", "a surface enclosing a volume "
      "(small holes are capped)", pdsim.GeometryError, "encloses no volume")  # fmt: skip
def _(ws):
    pdsim.load_mesh(ws.input("sheet.obj", "v 0 0 0\nv 0.3 0 0\nv 0.3 0.2 0\nv 0 0.2 0\nf 1 2 3\nf 1 3 4\n"))


@case("empty_obj", A_MESH, "an OBJ file without faces", "a file holding triangles", pdsim.GeometryError, "empty")
def _(ws):
    pdsim.load_mesh(ws.input("empty.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"))


@case("mesh_suffix", A_MESH, "a mesh file of an unknown type", ".obj, .stl, .ply, .glb, .gltf, .off",
      pdsim.GeometryError, "'.xyz'", ".obj")  # fmt: skip
def _(ws):
    pdsim.load_mesh(ws.input("model.xyz", "0 0 0\n"))


@case("mesh_missing", A_MESH, "a mesh path that does not exist", "an existing file", pdsim.GeometryError,
      "no such file")  # fmt: skip
def _(ws):
    pdsim.load_mesh(ws.root / "missing.obj")


@case("stl_corrupt", A_MESH, "an STL file of garbage bytes", "an ASCII or binary STL", pdsim.GeometryError,
      "not a readable STL file", "84 + 50 x N bytes")  # fmt: skip
def _(ws):
    pdsim.load_mesh(ws.input("part.stl", b"solid x\n\x00\xff\xfe garbage \x80\x81" * 10))


@case("stl_holds_obj", A_MESH, "an OBJ file named .stl", "an STL, or the file renamed to .obj", pdsim.GeometryError,
      "holds OBJ text", "rename it to .obj")  # fmt: skip
def _(ws):
    pdsim.load_mesh(ws.input("part.stl", _box_mesh_text()))


@case("mesh_scale_zero", A_MESH, "load_mesh(scale=0)", "a scale > 0", pdsim.ParameterError, "scale=0", "(0, inf)")
def _(ws):
    pdsim.load_mesh(ws.input("box.obj", _box_mesh_text()), scale=0.0)


@case("mesh_position", A_MESH, "load_mesh(position=(1, 2))", "3 finite numbers [m]", pdsim.ParameterError,
      "position=", "3 finite numbers")  # fmt: skip
def _(ws):
    pdsim.load_mesh(ws.input("box.obj", _box_mesh_text()), position=(1.0, 2.0))


@case("mesh_fit_and_scale", A_MESH, "load_mesh(scale=2, fit_size=0.3)", "one of scale and fit_size",
      pdsim.ParameterError, "fit_size=0.3", "scale")  # fmt: skip
def _(ws):
    pdsim.load_mesh(ws.input("box.obj", _box_mesh_text()), scale=2.0, fit_size=0.3)


@case("mesh_rotation", A_MESH, "load_mesh(rotation=(90, 0))", "3 Euler angles [degrees] or a 3x3 rotation matrix",
      pdsim.ParameterError, "rotation=", "Euler angles")  # fmt: skip
def _(ws):
    pdsim.load_mesh(ws.input("box.obj", _box_mesh_text()), rotation=(90.0, 0.0))


@case("mesh_up_axis", A_MESH, "load_mesh(up_axis='X')", "'Y' or 'Z'", pdsim.ParameterError, "up_axis='X'")
def _(ws):
    pdsim.load_mesh(ws.input("box.obj", _box_mesh_text()), up_axis="X")


@case("face_indices", A_MESH, "shape_from_arrays with a face index past the last vertex",
      "integer vertex indices in [0, vertex count)", pdsim.GeometryError, "vertex indices", "[0, 8)")  # fmt: skip
def _(ws):
    box = pdsim.box((1.0, 1.0, 1.0))
    faces = box.faces.copy()
    faces[0, 0] = 8
    pdsim.shape_from_arrays(box.vertices, faces, name="bad_faces")


@case("nan_vertex", A_MESH, "a NaN vertex coordinate", "finite coordinates", pdsim.GeometryError, "non-finite")
def _(ws):
    box = pdsim.box((1.0, 1.0, 1.0))
    v = box.vertices.copy()
    v[2, 1] = np.nan
    pdsim.shape_from_arrays(v, box.faces, name="nan_vertex")


@case("mesh_scale_1e9", A_MESH, "load_mesh(scale=1e-9): a 0.3 m part shrunk below 0.1 micrometre",
      "a mesh in metres", pdsim.GeometryError, "across", "wrong units")  # fmt: skip
def _(ws):
    pdsim.load_mesh(ws.input("box.obj", _box_mesh_text()), scale=1.0e-9)


@case("box_size", A_MESH, "pdsim.box with a negative edge", "three edge lengths > 0 [m]", pdsim.ParameterError,
      "size=", "edge lengths > 0")  # fmt: skip
def _(ws):
    pdsim.box((0.3, -0.1, 0.1))


@case("sphere_subdivisions", A_MESH, "pdsim.sphere(subdivisions=9)", "an integer in [1, 7]",
      pdsim.ParameterError, "subdivisions=9", "[1, 7]")  # fmt: skip
def _(ws):
    pdsim.sphere(0.1, subdivisions=9)


# -- materials --------------------------------------------------------------------------------------------------
A_MAT = "materials"


@case("poisson_half", A_MAT, "Poisson's ratio 0.5 (incompressible)", "(-1, 0.5)", pdsim.ParameterError,
      "poisson_ratio=0.5", "(-1, 0.5)")  # fmt: skip
def _(ws):
    _material(poisson_ratio=0.5)


@case("density_negative", A_MAT, "a negative density", "a density > 0 [kg/m^3]", pdsim.ParameterError,
      "density=-1000.0", "(0, inf)")  # fmt: skip
def _(ws):
    _material(density=-1000.0)


@case("modulus_nan", A_MAT, "Young's modulus NaN", "a finite number > 0 [Pa]", pdsim.ParameterError,
      "youngs_modulus=nan", "finite")  # fmt: skip
def _(ws):
    _material(youngs_modulus=float("nan"))


@case("two_fracture_laws", A_MAT, "both fracture_energy and critical_stretch", "one of the two",
      pdsim.ParameterError, "critical_stretch=", "None when fracture_energy is given")  # fmt: skip
def _(ws):
    _material(fracture_energy=100.0, critical_stretch=0.01)


@case("failure_without_yield", A_MAT, "failure_plastic_strain without a yield stress",
      "failure_plastic_strain only with yield_stress", pdsim.ParameterError, "failure_plastic_strain=",
      "unless yield_stress")  # fmt: skip
def _(ws):
    _material(failure_plastic_strain=0.2)


@case("correlation_without_scatter", A_MAT, "a strength_correlation_length without a Weibull modulus",
      "strength_correlation_length only with strength_weibull_modulus", pdsim.ParameterError,
      "strength_correlation_length=0.05", "unless strength_weibull_modulus")  # fmt: skip
def _(ws):
    _material(critical_stretch=0.01, strength_correlation_length=0.05)


@case("jitter_unbreakable", A_MAT, "a sampling_jitter on a material that never breaks",
      "sampling_jitter only on a material that breaks", pdsim.ParameterError, "sampling_jitter=0.5",
      "never breaks")  # fmt: skip
def _(ws):
    _material(sampling_jitter=0.5)


@case("contact_restitution_range", A_MAT, "Material(contact_restitution=0.0)", "(0, 1], or None",
      pdsim.ParameterError, "contact_restitution=0.0", "(0, 1]")  # fmt: skip
def _(ws):
    _material(contact_restitution=0.0)


@case("contact_friction_negative", A_MAT, "Material(contact_friction=-0.2)", "a Coulomb coefficient >= 0, or None",
      pdsim.ParameterError, "contact_friction=-0.2", "[0, inf)")  # fmt: skip
def _(ws):
    _material(contact_friction=-0.2)


# -- bodies -----------------------------------------------------------------------------------------------------
A_BODY = "bodies and spacing"


@case("spacing_too_large", A_BODY, "a spacing larger than the body", "a spacing up to the smallest extent",
      pdsim.ParameterError, "spacing=0.2", "(0, 0.1]", "pebble")  # fmt: skip
def _(ws):
    pdsim.PeridynamicBody(pdsim.box((0.1, 0.1, 0.1), name="pebble"), _material(), spacing=0.2)


@case("spacing_zero", A_BODY, "spacing 0", "a spacing > 0 [m]", pdsim.ParameterError, "spacing=0.0", "(0, inf)")
def _(ws):
    pdsim.PeridynamicBody(pdsim.box((0.1, 0.1, 0.1)), _material(), spacing=0.0)


@case("spacing_in_mm", A_BODY, "a spacing given in millimetres (5 for 5 mm) on a 0.3 m part",
      "a spacing in metres", pdsim.ParameterError, "spacing=5", "did you mean millimetres",
      "spacing=0.005")  # fmt: skip
def _(ws):
    pdsim.PeridynamicBody(pdsim.box((0.3, 0.2, 0.1)), _material(), spacing=5.0)


@case("mesh_in_mm", A_BODY, "a part modelled in millimetres read as metres (300 m across at spacing 5 mm)",
      "at most 2e8 lattice points", pdsim.ParameterError, "spacing=0.005", "lattice points",
      "did you mean millimetres", "scale=0.001")  # fmt: skip
def _(ws):
    part = pdsim.load_mesh(ws.input("part_mm.obj", _box_mesh_text(scale=1000.0)))
    pdsim.PeridynamicBody(part, _material(), spacing=0.005)


@case("lattice_overflow", A_BODY, "a mesh scale so large the lattice count overflows int64 (was a numpy error or "
      "an out-of-memory kill)", "at most 2e8 lattice points", pdsim.ParameterError, "spacing=0.01",
      "lattice points")  # fmt: skip
def _(ws):
    part = pdsim.load_mesh(ws.input("box.obj", _box_mesh_text()), scale=1.0e8)
    pdsim.PeridynamicBody(part, _material(), spacing=0.01)


@case("mesh_1e6_too_small", A_BODY, "a mesh scaled by 1e-6 (its peridynamic constants overflow float32; was a "
      "ZeroDivisionError in the run)", "a spacing whose constants fit float32", pdsim.ParameterError,
      "overflow float32", "wrong units")  # fmt: skip
def _(ws):
    part = pdsim.load_mesh(ws.input("box.obj", _box_mesh_text()), scale=1.0e-6)
    scene = _scene()
    scene.add_peridynamic_body(part, _material(), spacing=2.5e-8)
    scene.build_solvers(device="cpu")


@case("horizon_factor", A_BODY, "horizon_factor=10", "[1.5, 8]", pdsim.ParameterError, "horizon_factor=10",
      "[1.5, 8]")  # fmt: skip
def _(ws):
    pdsim.PeridynamicBody(pdsim.box((0.1, 0.1, 0.1)), _material(), spacing=0.02, horizon_factor=10)


@case("surface_correction", A_BODY, "an unknown surface correction", "'directional', 'family' or 'none'",
      pdsim.ParameterError, "surface_correction='madenci'", "'directional'")  # fmt: skip
def _(ws):
    pdsim.PeridynamicBody(pdsim.box((0.1, 0.1, 0.1)), _material(), spacing=0.02, surface_correction="madenci")


@case("rigid_handoff", A_BODY, "rigid_handoff='yes'", "None, False, True or a pdsim.RigidHandoff",
      pdsim.ParameterError, "rigid_handoff='yes'", "pdsim.RigidHandoff")  # fmt: skip
def _(ws):
    pdsim.PeridynamicBody(pdsim.box((0.1, 0.1, 0.1)), _material(), spacing=0.02, rigid_handoff="yes")


@case("rigid_handoff_frames", A_BODY, "pdsim.RigidHandoff(frames=0)", "an integer >= 1", pdsim.ParameterError,
      "frames=0", ">= 1")  # fmt: skip
def _(ws):
    pdsim.RigidHandoff(frames=0)


@case("rigid_handoff_fixed", A_BODY, "pdsim.RigidHandoff(fixed='yes')", "True or False", pdsim.ParameterError,
      "fixed='yes'", "True or False")  # fmt: skip
def _(ws):
    pdsim.RigidHandoff(fixed="yes")


@case("rigid_handoff_in_flight", A_BODY, "pdsim.RigidHandoff(in_flight='yes')", "True or False",
      pdsim.ParameterError, "in_flight='yes'", "True or False")  # fmt: skip
def _(ws):
    pdsim.RigidHandoff(in_flight="yes")


@case("material_rigid_handoff", A_BODY, "pdsim.Material(..., rigid_handoff='yes')", "True or False",
      pdsim.ParameterError, "rigid_handoff='yes'", "True or False")  # fmt: skip
def _(ws):
    pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25, rigid_handoff="yes")


# -- boundary conditions and loads ------------------------------------------------------------------------------
A_BC = "boundary conditions and loads"


@case("fix_empty_region", A_BC, "body.fix with a region that holds no particle", "a region with at least one point",
      pdsim.ParameterError, "region=", "at least one particle", "'beam'")  # fmt: skip
def _(ws):
    _beam(_scene()).fix(pdsim.BoxRegion(lo=(5.0, 5.0, 5.0), hi=(6.0, 6.0, 6.0)))


@case("region_not_region", A_BC, "body.fix('left end')", "a BoxRegion, SphereRegion, HalfSpace or a callable",
      pdsim.ParameterError, "region='left end'", "BoxRegion")  # fmt: skip
def _(ws):
    _beam(_scene()).fix("left end")


@case("conflicting_conditions", A_BC, "a set_velocity region overlapping a fix region",
      "one condition per point (one condition with the axes of both)", pdsim.ParameterError, "'pull'", "'clamp'",
      "already held")  # fmt: skip
def _(ws):
    body = _beam(_scene())
    body.fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(0.05, 1.0, 2.0)), name="clamp")
    body.set_velocity(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(0.12, 1.0, 2.0)), (0.1, 0.0, 0.0), name="pull")


@case("traction_no_surface", A_BC, "a traction whose region misses the body's surface",
      "a region that holds part of the surface", pdsim.ParameterError, "surface of 'beam'", "spans")  # fmt: skip
def _(ws):
    _beam(_scene()).add_traction(pdsim.BoxRegion(lo=(5.0, 5.0, 5.0), hi=(6.0, 6.0, 6.0)), (1.0e3, 0.0, 0.0))


@case("bad_axes", A_BC, "axes='xw'", "a non-empty combination of 'x', 'y', 'z'", pdsim.ParameterError,
      "axes='xw'", "'x', 'y', 'z'")  # fmt: skip
def _(ws):
    _beam(_scene()).fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(0.05, 1.0, 2.0)), axes="xw")


@case("release_before_start", A_BC, "release before start", "release > start [s]", pdsim.ParameterError,
      "release=0.1", "(0.2, inf)")  # fmt: skip
def _(ws):
    _beam(_scene()).fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(0.05, 1.0, 2.0)), start=0.2, release=0.1)


# -- scene --------------------------------------------------------------------------------------------------------
A_SCENE = "scene"


@case("scene_name_empty", A_SCENE, 'Scene(name="")', "a non-empty scene name without '/'", pdsim.ParameterError,
      "name=''", "non-empty scene name")  # fmt: skip
def _(ws):
    pdsim.Scene(name="")


@case("collider_not_collider", A_SCENE, "scene.add_collider(pdsim.box(...)) (a shape, not a collider)",
      "MeshCollider(shape), SphereProjectile, BoxProjectile, MeshProjectile(shape)", pdsim.ParameterError,
      "collider='SolidShape'", "MeshCollider(shape)")  # fmt: skip
def _(ws):
    _scene().add_collider(pdsim.box((1.0, 1.0, 1.0)))


@case("frames_zero", A_SCENE, "Scene(frames=0)", "an integer >= 1", pdsim.ParameterError, "frames=0",
      "an integer >= 1")  # fmt: skip
def _(ws):
    pdsim.Scene(frames=0)


@case("up_axis", A_SCENE, "Scene(up_axis='X')", "'Y' or 'Z'", pdsim.ParameterError, "up_axis='X'", "'Y' or 'Z'")
def _(ws):
    pdsim.Scene(up_axis="X")


@case("fps_zero", A_SCENE, "Scene(fps=0)", "(0, 1000]", pdsim.ParameterError, "fps=0", "(0, 1000]")
def _(ws):
    pdsim.Scene(fps=0)


@case("time_scale_and_frame_time", A_SCENE, "both time_scale and frame_time", "one of the two",
      pdsim.ParameterError, "time_scale=0.2", "give one of the two")  # fmt: skip
def _(ws):
    pdsim.Scene(time_scale=0.2, frame_time=1.0e-3)


@case("gravity_two_numbers", A_SCENE, "gravity=(0, -9.81)", "3 finite numbers [m/s^2]", pdsim.ParameterError,
      "gravity=", "3 finite numbers")  # fmt: skip
def _(ws):
    pdsim.Scene(gravity=(0.0, -9.81))


@case("not_a_body", A_SCENE, "scene.add_body('beam')", "a pdsim body", pdsim.ParameterError, "body='beam'",
      "PeridynamicBody")  # fmt: skip
def _(ws):
    _scene().add_body("beam")


@case("duplicate_name", A_SCENE, "two bodies named 'beam'", "unique body names", pdsim.ParameterError,
      "name='beam'", "not already used")  # fmt: skip
def _(ws):
    scene = _scene()
    _beam(scene)
    _beam(scene, center=(0.15, 0.5, 0.5))


@case("usd_name_clash", A_SCENE, "bodies 'body 1' and 'body_1' (one USD prim /World/body_1)",
      "names whose USD identifiers differ", pdsim.ParameterError, "'body 1'", "'body_1'", "/World/body_1")  # fmt: skip
def _(ws):
    scene = _scene()
    _beam(scene, name="body 1")
    _beam(scene, name="body_1", center=(0.15, 0.5, 0.5))


@case("body_named_ground", A_SCENE, "a body named 'ground' in a scene with a ground plane",
      "a name other than the ground's prim", pdsim.ParameterError, "'ground'", "/World/ground")  # fmt: skip
def _(ws):
    scene = _scene()
    _beam(scene, name="ground")
    scene.add_ground_plane(height=0.0)


@case("empty_scene", A_SCENE, "a scene without bodies", "at least one body", pdsim.ParameterError, "bodies=[]",
      "at least one body")  # fmt: skip
def _(ws):
    _scene().build_solvers(device="cpu")


@case("bodies_overlap", A_SCENE, "two bodies that interpenetrate at the start", "bodies that touch at most",
      pdsim.GeometryError, "'left' and 'right' overlap", "m^3")  # fmt: skip
def _(ws):
    scene = _scene()
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.2)), _material(), spacing=0.02, name="left")
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.2), center=(0.15, 0.0, 0.0)), _material(), 0.02, name="right")
    ws.earlier_cache()
    _run(scene, ws)


@case("fem_pd_overlap", A_SCENE, "an FEM slab inside a peridynamic block", "bodies that touch at most",
      pdsim.GeometryError, "'block' and 'slab' overlap")  # fmt: skip
def _(ws):
    scene = _scene()
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.2)), _material(), spacing=0.02, name="block")
    scene.add_fem_body(pdsim.box_tet_mesh((0.4, 0.4, 0.05), (4, 4, 1), center=(0, 0, 0.05)), _material(), name="slab")
    scene.build_solvers(device="cpu")


@case("projectile_inside", A_SCENE, "a projectile that starts inside a body", "a projectile outside the body",
      pdsim.GeometryError, "projectile 'ball'", "starts inside body 'plate'")  # fmt: skip
def _(ws):
    scene = _scene()
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.05)), _material(), spacing=0.01, name="plate")
    scene.add_collider(pdsim.SphereProjectile(0.03, center=(0.0, 0.0, 0.02), velocity=(0, 0, -10), name="ball"))
    scene.build_solvers(device="cpu")


@case("rigid_body_inside", A_SCENE, "a rigid body (Scene.add_rigid_body) that starts inside a body",
      "a rigid body outside the body", pdsim.GeometryError, "rigid body 'ball'",
      "starts inside body 'plate'")  # fmt: skip
def _(ws):
    scene = _scene()
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.05)), _material(), spacing=0.01, name="plate")
    scene.add_rigid_body(pdsim.SphereShape(0.03), density=7850.0, position=(0.0, 0.0, 0.02), name="ball")
    scene.build_solvers(device="cpu")


@case("rigid_body_mass_and_density", A_SCENE, "Scene.add_rigid_body(..., density=..., mass=...) (both given)",
      "exactly one of density [kg/m^3] and mass [kg]", pdsim.ParameterError, "density=7850",
      "exactly one of density")  # fmt: skip
def _(ws):
    _scene().add_rigid_body(pdsim.SphereShape(0.03), density=7850.0, mass=1.0)


@case("rigid_body_restitution", A_SCENE, "Scene.add_rigid_body(..., restitution=1.5)",
      "restitution None or in [0, 1]", pdsim.ParameterError, "restitution=1.5", "restitution")  # fmt: skip
def _(ws):
    _scene().add_rigid_body(pdsim.SphereShape(0.03), density=7850.0, restitution=1.5, name="ball")


@case("rigid_body_with_projectile", A_SCENE, "a rigid body and a kinematic projectile in one scene (they do not "
      "collide with each other)", "rigid bodies only (Scene.add_rigid_body), or no rigid body",
      pdsim.FeatureNotAvailableError, "kinematic projectiles", "Scene.add_rigid_body")  # fmt: skip
def _(ws):
    scene = _scene()
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.05)), _material(), spacing=0.05, name="plate")
    scene.add_rigid_body(pdsim.SphereShape(0.03), density=7850.0, position=(0.0, 0.0, 0.2), name="ball")
    scene.add_collider(pdsim.SphereProjectile(0.03, center=(0.0, 0.0, -0.2), name="bullet"))
    scene.build_solvers(device="cpu")


@case("ground_above", A_SCENE, "a ground plane above the bodies (was reported as 'time step too large')",
      "a ground plane at or below the bodies", pdsim.GeometryError, "starts below the ground plane",
      "height 0.5 m")  # fmt: skip
def _(ws):
    scene = _scene()
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.1), center=(0, 0, 0.05)), _material(), 0.02, name="slab")
    scene.add_ground_plane(height=0.5)
    scene.build_solvers(device="cpu")


# -- FEM meshes -------------------------------------------------------------------------------------------------
A_FEM = "FEM meshes"


@case("ground_restitution_range", A_SCENE, "Scene.add_ground_plane(restitution=1.5)", "(0, 1], or None",
      pdsim.ParameterError, "restitution", "1.5")  # fmt: skip
def _(ws):
    _scene().add_ground_plane(restitution=1.5)


@case("sliver_element", A_FEM, "a tetrahedral mesh with a sliver (quality 3e-3: its stable step is 1/350 of the "
      "median element's)", "elements of quality >= min_quality (default 0.02), or a lower min_quality",
      pdsim.GeometryError, "is degenerate", "quality 0.00", "min_quality=0.02", "of the median element's")  # fmt: skip
def _(ws):
    v, t = _sliver_mesh()
    pdsim.tet_mesh_from_arrays(v, t, name="bracket")


@case("sliver_tetmesh_direct", A_FEM, "a TetMesh built directly (unchecked) with a sliver, in a scene",
      "elements of quality >= the mesh's min_quality", pdsim.GeometryError, "bracket", "is degenerate")  # fmt: skip
def _(ws):
    v, t = _sliver_mesh()
    scene = _scene()
    scene.add_fem_body(pdsim.TetMesh(v, t.astype(np.int32), name="bracket"), _material())
    scene.build_solvers(device="cpu")


@case("inverted_element", A_FEM, "two elements folded over their shared face", "a valid, non-overlapping mesh",
      pdsim.GeometryError, "inverted")  # fmt: skip
def _(ws):
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 1.0], [0.3, 0.3, 0.5]])
    pdsim.tet_mesh_from_arrays(v, [[0, 1, 2, 3], [0, 2, 1, 4]], name="folded")


@case("fem_ground_restitution", A_FEM, "an FEM body with Scene.add_ground_plane(restitution=0.3)",
      "a ground plane without restitution, or a PeridynamicBody", pdsim.FeatureNotAvailableError,
      "restitution=0.3", "without restitution")  # fmt: skip
def _(ws):
    scene = _scene()
    scene.add_fem_body(pdsim.box_tet_mesh((0.1, 0.1, 0.1), (2, 2, 2), center=(0.0, 0.0, 0.5)), _material(), name="b")
    scene.add_ground_plane(restitution=0.3)
    scene.build_solvers(device="cpu")


@case("fem_measure", A_FEM, "FemBody(measure='cauchy')", "'linear', 'corotated' or 'green'", pdsim.ParameterError,
      "measure='cauchy'", "'corotated'")  # fmt: skip
def _(ws):
    pdsim.FemBody(pdsim.box_tet_mesh((1, 1, 1), (1, 1, 1)), _material(), measure="cauchy")


@case("edge_length_for_tetmesh", A_FEM, "edge_length with a ready TetMesh", "None (a TetMesh is not remeshed)",
      pdsim.ParameterError, "edge_length=0.1", "not remeshed")  # fmt: skip
def _(ws):
    pdsim.FemBody(pdsim.box_tet_mesh((1, 1, 1), (1, 1, 1)), _material(), edge_length=0.1)


@case("fem_mesh_in_mm", A_FEM, "an FEM part modelled in millimetres read as metres, edge_length 5 mm",
      "at most 2e7 elements", pdsim.ParameterError, "edge_length=0.005", "did you mean millimetres")  # fmt: skip
def _(ws):
    part = pdsim.load_mesh(ws.input("part_mm.obj", _box_mesh_text(scale=1000.0)))
    pdsim.FemBody(part, _material(), edge_length=0.005)


@case("mesher_crash", A_FEM, "fTetWild crashing on a surface (a native abort, forced here; a thin part does it)",
      "a surface the mesher can fill (thicker, or a smaller edge_length)", pdsim.GeometryError,
      "fTetWild crashed (SIGABRT)", "thicken the part", needs_ftetwild=True)  # fmt: skip
def _(ws):
    with _patched(pdsim.fem.mesh, "_CHILD_TEST_HOOK", "import os; os.abort()"):
        pdsim.FemBody(pdsim.box((0.3, 0.2, 0.1), name="bracket"), _material(), edge_length=0.05)


@case("thin_part", A_FEM, "a closed box 1 m x 1 m x 10 um meshed at the default edge length",
      "a part thicker than the mesher's envelope", pdsim.GeometryError, "too thin", "thicken the part",
      needs_ftetwild=True)  # fmt: skip
def _(ws):
    pdsim.FemBody(pdsim.box((1.0, 1.0, 1.0e-5), name="foil"), _material())


# -- runs and output --------------------------------------------------------------------------------------------
A_RUN = "runs and output"
A_WRITE = "failures during a run (the finished frames stay)"


@case("out_suffix", A_RUN, "an output path ending in .abc", ".usdc, .usda or .usd", pdsim.ParameterError,
      "out=", "cache.abc", ".usdc")  # fmt: skip
def _(ws):
    _run(_tiny(), ws, ws.root / "cache.abc")


@case("run_layout", A_RUN, "Scene.run(out, layout='zip')", "'file' (one self-contained file) or 'clips'",
      pdsim.ParameterError, "layout='zip'", "'file'", "'clips'")  # fmt: skip
def _(ws):
    _run(_tiny(), ws, ws.out, layout="zip")


@case("out_folder_missing", A_RUN, "an output folder that does not exist", "a path in an existing folder",
      pdsim.ParameterError, "no_such_dir", "existing folder")  # fmt: skip
def _(ws):
    _run(_tiny(), ws, ws.root / "no_such_dir" / "out.usdc")


@case("out_is_folder", A_RUN, "an output path that is an existing folder", "a file path", pdsim.ParameterError,
      "a file path, not a folder")  # fmt: skip
def _(ws):
    _run(_tiny(), ws, ws.folder("cache.usdc"))


@case("out_read_only", A_RUN, "an output folder nobody can write to (/proc)", "a writable folder",
      pdsim.ParameterError, "/proc/out.usdc", "can write to")  # fmt: skip
def _(ws):
    _run(_tiny(), ws, "/proc/out.usdc")


@case("frames_folder_blocked", A_RUN, "a file named like the cache's frame folder (out.frames)",
      "a free <stem>.frames path", pdsim.ParameterError, "out.frames", "is free")  # fmt: skip
def _(ws):
    ws.input("out.frames", "not a folder")
    _run(_tiny(), ws)


@case("debris_negative", A_RUN, "Scene.run(out, debris_particles=-1)", "an integer >= 0 (0: no debris)",
      pdsim.ParameterError, "debris_particles=-1", ">= 0")  # fmt: skip
def _(ws):
    _run(_tiny(), ws, debris_particles=-1)


@case("crack_events_fem", A_RUN, "Scene.run(out, crack_events=True) with an FEM body",
      "peridynamic bodies only, or crack_events=False", pdsim.FeatureNotAvailableError, "crack_events=True", "'bar'",
      "peridynamic")  # fmt: skip
def _(ws):
    scene = _scene(gravity=(0.0, 0.0, 0.0))
    scene.add_fem_body(pdsim.box_tet_mesh((0.1, 0.1, 0.1), (1, 1, 1), center=(0.0, 0.0, 0.5)), _material(), name="bar")
    _run(scene, ws, crack_events=True)


@case("run_frames_zero", A_RUN, "scene.run(frames=0)", "an integer >= 1", pdsim.ParameterError, "frames=0")
def _(ws):
    ws.earlier_cache()
    _run(_tiny(), ws, frames=0)


@case("dt_negative", A_RUN, "dt=-1e-5", "a step > 0 [s]", pdsim.ParameterError, "dt=-1e-05", "(0, inf)")
def _(ws):
    _run(_tiny(), ws, dt=-1.0e-5)


@case("dt_tiny", A_RUN, "dt=1e-12 (4e10 substeps a frame)", "at most 1e7 substeps per frame",
      pdsim.ParameterError, "dt=1e-12", "substeps per frame", "4.17e+10")  # fmt: skip
def _(ws):
    scene = pdsim.Scene(fps=24.0, frames=2)
    _beam(scene)
    ws.earlier_cache()
    _run(scene, ws, dt=1.0e-12)


@case("automatic_step_tiny", A_RUN, "a steel body at 1 cm spacing with 20 s frames (2e7 automatic substeps)",
      "at most 1e7 substeps per frame", pdsim.ParameterError, "spacing=0.01", "substeps")  # fmt: skip
def _(ws):
    scene = pdsim.Scene(fps=24.0, frames=2, frame_time=20.0)
    steel = pdsim.Material(density=7850.0, youngs_modulus=2.0e11, poisson_ratio=0.3)
    scene.add_peridynamic_body(pdsim.box((0.1, 0.1, 0.1)), steel, spacing=0.01, name="billet")
    _run(scene, ws)


@case("memory", A_RUN, "a spacing and horizon whose bonds need about 28 GB (8 GB free)",
      "a scene that fits the free memory", pdsim.ParameterError, "spacing=0.01", "the most free memory here is 8 GB",
      "spacing >=")  # fmt: skip
def _(ws):
    with _free_memory(8.0e9):
        scene = pdsim.Scene(fps=24.0, frames=2)
        scene.add_peridynamic_body(pdsim.box((0.46, 0.46, 0.46)), _material(), 0.01, horizon_factor=8.0, name="block")
        _run(scene, ws)


@case("disk_full", A_RUN, "a cache larger than the free disk space (1 MB free)", "a folder with room for the cache",
      pdsim.ParameterError, "room for the cache", "1 MB free")  # fmt: skip
def _(ws):
    scene = pdsim.Scene(fps=24.0, frames=48)
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.2)), _material(), spacing=0.02, name="block")
    with _patched(pdsim.memory, "free_disk_space", lambda folder: 1.0e6):
        _run(scene, ws)


@case("spacing_150_million", A_RUN, "a spacing asking for 150 million particles (100 GB free)",
      "a spacing whose body fits in the free memory (refused before any sampling, in under 5 s)",
      pdsim.ParameterError, "about 1.51e+08 particles", "spacing >=")  # fmt: skip
def _(ws):
    with _free_memory(100.0e9):
        _scene().add_peridynamic_body(pdsim.box((1.0, 1.5, 1.0)), _material(), (1.5 / 150.0e6) ** (1 / 3), name="b")


@contextlib.contextmanager
def _failing_disk(fails, err=errno.ENOSPC):
    """The cache's layer exports raise OSError(err) for the targets ``fails`` accepts; from then on (or once the
    yielded state's "failed" is set) the disk has 0 B free (before: 1 TB, so that the pre-flight passes)."""
    state = {"failed": False}
    real = pdsim.output.usd_stream.export_layer

    def export(layer, target):
        if fails(Path(target)):
            state["failed"] = True
            raise OSError(err, os.strerror(err), str(target))
        real(layer, target)

    def free(folder):
        return 0.0 if state["failed"] else 1.0e12

    with _patched(pdsim.output.usd_stream, "export_layer", export), _patched(pdsim.memory, "free_disk_space", free):
        yield state


@case("write_disk_full_frame", A_WRITE, "the disk fills up while frame 2's layer is written",
      "a disk with room for the cache; the frames finished before stay", pdsim.errors.OutputWriteError,
      "frame.000002.usdc", "No space left on device", "0 B free", "holds frames 0..1", keeps_frames=True)  # fmt: skip
def _(ws):
    with _failing_disk(lambda t: t.name.startswith("frame.000002")):
        _run(_tiny_frames(3), ws)


@case("write_disk_full_top", A_WRITE, "the disk fills up while the top-level layer is written (frame 2)",
      "a disk with room for the cache; the frames finished before stay", pdsim.errors.OutputWriteError,
      "out.usdc: No space left on device", "holds frames 0..1", keeps_frames=True)  # fmt: skip
def _(ws):
    count = []

    def top(t):
        count.append(t.name == ws.out.name)
        return sum(count) > 2 and t.name == ws.out.name

    with _failing_disk(top):
        _run(_tiny_frames(3), ws)


@case("write_disk_full_checkpoint", A_WRITE, "the disk fills up while a checkpoint is written",
      "a disk with room for the checkpoint; the frames finished before stay", pdsim.errors.OutputWriteError,
      ".out.checkpoint.npz.tmp", "No space left on device", "holds frames 0..1", keeps_frames=True)  # fmt: skip
def _(ws):
    with _failing_disk(lambda t: False) as disk:

        def write_chunk(self, chunk):  # a write to a full disk: OSError(ENOSPC) without a file name
            disk["failed"] = True
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        with _patched(pdsim.checkpoint._ChunkedFile, "write_chunk", write_chunk):
            _run(_tiny_frames(3), ws, checkpoint_interval_s=0.0)


@case("write_read_only", A_WRITE, "the output folder turned read-only during the run (frame 2)",
      "a folder that stays writable; the frames finished before stay", pdsim.errors.OutputWriteError,
      "frame.000002.usdc", "Read-only file system", "holds frames 0..1", keeps_frames=True)  # fmt: skip
def _(ws):
    with _failing_disk(lambda t: t.name.startswith("frame.000002"), err=errno.EROFS):
        _run(_tiny_frames(3), ws)


@case("lattice_leader_nan", A_WRITE, "lattice leaders moving 1e38 m per step (NaN displacements on the device)",
      "leader velocities in metres per step", pdsim.InstabilityError, "the leaders added with velocity (1e+38, 0, 0)",
      "metres per step", "holds frames 0..0", keeps_frames=True)  # fmt: skip
def _(ws):
    body = LatticeBody.block(Lattice.square(1.0), (8, 6), name="block")
    x = body.rest_positions[: body.body_count, 0]
    body.clamp(x < x.min() + 0.5)
    body.add_leaders(x > x.max() - 0.5, velocity=(1.0e38, 0.0, 0.0))
    scene = pdsim.Scene(frames=1)
    scene.add_body(body)
    _run(scene, ws)


def _tiny_frames(frames: int) -> pdsim.Scene:
    scene = pdsim.Scene(fps=100.0, frames=frames)
    _beam(scene)
    return scene


def _tiny() -> pdsim.Scene:
    scene = _scene()
    _beam(scene)
    return scene


# -- command line -------------------------------------------------------------------------------------------------
A_CLI = "command line"

SCRIPT = """
import pdsim


def build_scene():
    scene = pdsim.Scene(fps={fps}, frames=2, name="tiny")
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e5, poisson_ratio=0.3)
    beam = scene.add_peridynamic_body(pdsim.box((0.3, 0.1, 0.1), center=(0.15, 0.0, 0.5)), material, spacing=0.05,
                                      name="beam")
    beam.fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(0.05, 1.0, 2.0)))
{extra}    return scene
"""


def _script(ws: Workspace, extra: str = "", fps: float = 100.0) -> Path:
    body = textwrap.indent(textwrap.dedent(extra), "    ") if extra else ""
    return ws.input("scene.py", SCRIPT.format(extra=body, fps=fps))


def _cli(ws: Workspace, *args) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pdsim.cli", *map(str, args)],
        check=False,
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ws.root,
    )


def _cli_run(ws: Workspace, script, *args) -> subprocess.CompletedProcess:
    return _cli(ws, "run", script, "--device", "cpu", "--quiet", *args)


@case("cli_scene_not_py", A_CLI, "pdsim run scene.txt", "a Python scene script (*.py)", pdsim.ParameterError,
      "scene.txt", "*.py", cli=True)  # fmt: skip
def _(ws):
    return _cli_run(ws, ws.input("scene.txt", "x"), "--out", ws.out)


@case("cli_scene_missing", A_CLI, "pdsim run nope.py (no such file)", "an existing file", pdsim.ParameterError,
      "nope.py", "an existing file", cli=True)  # fmt: skip
def _(ws):
    return _cli_run(ws, ws.root / "nope.py", "--out", ws.out)


@case("cli_no_build_scene", A_CLI, "a scene script without build_scene()", "a script defining build_scene()",
      pdsim.ParameterError, "build_scene()", cli=True)  # fmt: skip
def _(ws):
    return _cli_run(ws, ws.input("empty_scene.py", "x = 1\n"), "--out", ws.out)


@case("cli_build_scene_not_scene", A_CLI, "build_scene() returning something else", "a pdsim.Scene",
      pdsim.ParameterError, "build_scene()", "pdsim.Scene", cli=True)  # fmt: skip
def _(ws):
    return _cli_run(ws, ws.input("dict_scene.py", "def build_scene():\n    return {}\n"), "--out", ws.out)


@case("cli_frames_zero", A_CLI, "pdsim run --frames 0", "an integer >= 1", pdsim.ParameterError, "frames=0",
      cli=True)  # fmt: skip
def _(ws):
    ws.earlier_cache()
    return _cli_run(ws, _script(ws), "--out", ws.out, "--frames", 0)


@case("cli_frames_fraction", A_CLI, "pdsim run --frames 2.5", "an integer >= 1", pdsim.ParameterError, "frames='2.5'",
      "an integer >= 1", cli=True)  # fmt: skip
def _(ws):
    return _cli_run(ws, _script(ws), "--out", ws.out, "--frames", "2.5")


@case("cli_dt_negative_word", A_CLI, "pdsim run --dt -1e-5 (a negative value written as its own word)",
      "a step > 0 [s]", pdsim.ParameterError, "dt=-1e-05", cli=True)  # fmt: skip
def _(ws):
    return _cli_run(ws, _script(ws), "--out", ws.out, "--dt", "-1e-5")


@case("cli_dt_negative", A_CLI, "pdsim run --dt=-1e-5", "a step > 0 [s]", pdsim.ParameterError, "dt=-1e-05",
      cli=True)  # fmt: skip
def _(ws):
    return _cli_run(ws, _script(ws), "--out", ws.out, "--dt=-1e-5")


@case("cli_out_folder_missing", A_CLI, "pdsim run --out no_such_dir/x.usdc", "a path in an existing folder",
      pdsim.ParameterError, "existing folder", cli=True)  # fmt: skip
def _(ws):
    return _cli_run(ws, _script(ws), "--out", ws.root / "no_such_dir" / "x.usdc")


@case("cli_out_is_folder", A_CLI, "pdsim run --out cache.usdc where cache.usdc is a folder", "a file path",
      pdsim.ParameterError, "a file path, not a folder", cli=True)  # fmt: skip
def _(ws):
    return _cli_run(ws, _script(ws), "--out", ws.folder("cache.usdc"))


@case("cli_preview_clip_cache_alone", A_CLI, "pdsim preview of a clip-layout cache copied without its .frames folder",
      "the cache with its frames folder beside it, or a packed cache", CacheError, "clip-layout cache", "missing",
      "pdsim pack", cli=True)  # fmt: skip
def _(ws):
    made = ws.folder("made") / "shot.usdc"  # a clip-layout cache and its frames folder
    done = _cli_run(ws, _script(ws), "--out", made, "--frames", 1, "--layout", "clips")
    assert done.returncode == 0, done.stderr
    alone = ws.folder("sent") / "shot.usdc"  # the top-level layer alone, as a file sent to a farm
    alone.write_bytes(made.read_bytes())
    return _cli(ws, "preview", alone, "--out", ws.folder("stills") / "still.png")


@case("cli_overlap", A_CLI, "a scene script whose bodies overlap", "bodies that touch at most", pdsim.GeometryError,
      "'beam' and 'beam2' overlap", cli=True)  # fmt: skip
def _(ws):
    extra = """
    scene.add_peridynamic_body(pdsim.box((0.3, 0.1, 0.1), center=(0.2, 0.0, 0.5)), material, spacing=0.05,
                               name="beam2")
    """
    ws.earlier_cache()
    return _cli_run(ws, _script(ws, extra), "--out", ws.out)


@case("cli_missing_mesh", A_CLI, "a scene script loading a mesh file that is not there", "an existing file",
      pdsim.GeometryError, "part.stl", "no such file", cli=True)  # fmt: skip
def _(ws):
    return _cli_run(ws, _script(ws, 'pdsim.load_mesh("part.stl")\n'), "--out", ws.out)


@case("cli_device_cuda", A_CLI, "pdsim run --device cuda on a machine without CUDA", "'cpu'", pdsim.ParameterError,
      "device='cuda'", "no CUDA device", cli=True, skip_with_cuda=True)  # fmt: skip
def _(ws):
    return _cli(ws, "run", _script(ws), "--device", "cuda", "--quiet", "--out", ws.out)


@case("cli_dt_tiny", A_CLI, "pdsim run --dt 1e-12 (4e10 substeps a frame)", "at most 1e7 substeps per frame",
      pdsim.ParameterError, "dt=1e-12", "substeps per frame", cli=True)  # fmt: skip
def _(ws):
    ws.earlier_cache()
    return _cli_run(ws, _script(ws, fps=24.0), "--out", ws.out, "--dt", "1e-12")


@case("cli_out_read_only", A_CLI, "pdsim run --out /proc/out.usdc (a folder nobody can write to)",
      "a writable folder", pdsim.ParameterError, "can write to", cli=True)  # fmt: skip
def _(ws):
    return _cli_run(ws, _script(ws), "--out", "/proc/out.usdc")


@case("cli_out_empty", A_CLI, 'pdsim run --out ""', "a path ending in .usdc, .usda or .usd", pdsim.ParameterError,
      "out=''", ".usdc", cli=True)  # fmt: skip
def _(ws):
    ws.earlier_cache("tiny.usdc")
    return _cli_run(ws, _script(ws), "--out", "")


# -- the user's scene script (exit status 2) ----------------------------------------------------------------------
A_SCRIPT = "exceptions of the scene script (exit status 2)"


@case("script_syntax_error", A_SCRIPT, "a scene script with a syntax error", "a script Python can read",
      SyntaxError, "scene.py, line 4", "SyntaxError", cli=True, exit_code=2)  # fmt: skip
def _(ws):
    return _cli_run(ws, ws.input("scene.py", "import pdsim\n\n\ndef build_scene(:\n    pass\n"), "--out", ws.out)


@case("script_exception", A_SCRIPT, "build_scene raising (an index out of range)", "a build_scene that returns",
      IndexError, "scene.py, line 11", "IndexError: list index out of range", cli=True, exit_code=2)  # fmt: skip
def _(ws):
    ws.earlier_cache()
    return _cli_run(ws, _script(ws, "scene.bodies[5]\n"), "--out", ws.out)


@case("script_missing_import", A_SCRIPT, "a scene script importing a module that is not installed",
      "modules that import", ModuleNotFoundError, "scene.py, line 2", "No module named 'no_such_module'", cli=True,
      exit_code=2)  # fmt: skip
def _(ws):
    return _cli_run(ws, ws.input("scene.py", "import pdsim\nimport no_such_module\n"), "--out", ws.out)


@case("script_region_function", A_SCRIPT, "a region function (lambda) raising when pdsim calls it",
      "a function of points [n, 3] returning a mask [n]", IndexError, "scene.py, line 11", "index 7 is out of bounds",
      cli=True, exit_code=2)  # fmt: skip
def _(ws):
    return _cli_run(ws, _script(ws, "beam.fix(lambda x: x[:, 7] < 0.05)\n"), "--out", ws.out)


@case("script_run_script", A_SCRIPT, "a script run on its own (run_script) whose build_scene raises",
      "a build_scene that returns", ZeroDivisionError, "own.py, line 5", "ZeroDivisionError: division by zero",
      cli=True, exit_code=2)  # fmt: skip
def _(ws):
    text = "from pdsim.cli import run_script\n\n\ndef build_scene():\n    return 1 / 0\n\n\nrun_script(build_scene)\n"
    return subprocess.run(
        [sys.executable, str(ws.input("own.py", text)), "--out", str(ws.out), "--quiet", "--device", "cpu"],
        check=False, capture_output=True, text=True, timeout=300, cwd=ws.root,
    )  # fmt: skip


# ---------------------------------------------------------------------------------------------------------- running
def _stderr_lines(stderr: str) -> list[str]:
    """stderr lines of pdsim, without the line Warp's native library prints itself when it finds no CUDA driver."""
    return [ln for ln in stderr.splitlines() if ln.strip() and not ln.startswith("Warp CUDA warning:")]


def capture(c: Case, root: Path) -> str:
    """Runs a case in the empty folder ``root``; returns its message with ``root`` written as ``<tmp>``. Raises
    NoError when nothing failed, AssertionError when the failure is not the documented one (type, fragments, one
    line, for the command line: exit status 1, no traceback) or when the run left files behind."""
    ws = Workspace(root)
    if c.cli:
        proc = c.act(ws)
        if proc.returncode == 0:
            raise NoError(f"{c.id}: pdsim exited 0")
        assert proc.returncode == c.exit_code, (c.id, proc.returncode, proc.stderr)
        assert "Traceback (most recent call last)" not in proc.stdout + proc.stderr, proc.stderr
        lines = _stderr_lines(proc.stderr)
        if c.exit_code == 2:  # the scene script's exception: its line, then only the script's own frames
            assert lines[0].startswith("pdsim: error in scene script "), lines[0]
            message = lines[0][len("pdsim: ") :]
            frames = [ln for ln in lines[1:] if ln.lstrip().startswith("File ")]
            assert all(str(root) in ln for ln in frames), (c.id, proc.stderr)
        else:
            assert len(lines) == 1, (c.id, proc.stderr)
            assert lines[0].startswith("pdsim: error: "), lines[0]
            message = lines[0][len("pdsim: error: ") :]
    else:
        try:
            c.act(ws)
        except pdsim.PdsimError as exc:
            assert type(exc) is c.error, (c.id, type(exc), str(exc))
            message = str(exc)
        else:
            raise NoError(f"{c.id}: nothing was raised")
    assert "\n" not in message, message
    for frag in c.fragments:
        assert frag in message, f"{c.id}: {frag!r} not in {message!r}"
    left = ws.leftovers()
    if c.keeps_frames:  # the cache of the finished frames stays; nothing else does
        assert ws.out.is_file(), f"{c.id}: the finished frames were not kept"
        left = [p for p in left if not (p == ws.out.name or p.startswith(f"{ws.out.stem}.frames"))]
    assert not left, f"{c.id}: the failed run left {left}"
    return re.sub(r"run-\d{8}-\d{6}-\d+(-\d+)?", "<run>", message.replace(str(root), "<tmp>"))


def skip_reason(c: Case) -> str | None:
    """Why a case cannot run here, or None."""
    if c.needs_ftetwild and importlib.util.find_spec("pytetwild") is None:
        return "pytetwild is not installed"
    if c.skip_with_cuda and wp.get_cuda_device_count() > 0:
        return "this machine has a CUDA device"
    return None


# ------------------------------------------------------------------------------------------------------------- doc
HEADER = """# Bad inputs and their messages

Every mistake below stops pdsim before it simulates anything, with one line that names what is wrong and what is
allowed (the command line prints it as `pdsim: error: <message>` and exits with status 1, without a traceback).
Nothing is half-written: a run that fails leaves no cache and keeps an earlier cache at the same path as it was.

Three kinds of failure come later, and keep what was done:

- an exception raised by the user's own scene script (a syntax error, an exception in `build_scene`, a missing
  import, an exception in a region function): `pdsim run` and a script run with `run_script` print
  `pdsim: error in scene script <file>, line <n>: <exception>` and then only the script's own frames of the
  traceback, and exit with status 2;
- a write that fails during a run (disk full on a frame layer, on the top-level layer or on a checkpoint; the folder
  turned read-only): one line naming the path, the error and the free space, exit status 1, and the cache keeps every
  finished frame (the message says which);
- a divergence (exit status 3), whose line names the likely cause; the cache keeps every finished frame.

SIGTERM and Ctrl-C stop a run within 2 s, even while it writes a checkpoint (the write is abandoned, its temporary
file removed, the previous checkpoint kept); the next run on the same output removes the temporary files a killed
run left. `tests/test_stop_checkpoint.py` shows both.

The cases are in `tools/errors_catalogue.py`; `tests/test_errors_catalogue.py` runs each one and checks its message
against this page, and `python tools/errors_catalogue.py` rewrites the page. `<tmp>` stands for the folder of the
case. Pre-flight checks (`pdsim/preflight.py`) run in `Scene.build_solvers` and `Scene.run`: bodies overlapping or
below the ground, projectiles inside a body, USD names that clash, memory, substeps, mesh quality, the output folder
and its free space.
"""


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def render(messages: dict[str, str]) -> str:
    lines = [HEADER]
    total = 0
    areas = list(dict.fromkeys(c.area for c in CASES))
    for area in areas:
        lines += [
            f"\n## {area[0].upper() + area[1:]}\n",
            "| case | what is wrong | message | what is allowed |",
            "|---|---|---|---|",
        ]
        for c in (c for c in CASES if c.area == area):
            total += 1
            msg = messages.get(c.id)
            text = f"`{_cell(msg)}`" if msg else "(not run here)"
            lines.append(f"| `{c.id}` | {_cell(c.wrong)} | {text} | {_cell(c.allowed)} |")
    lines.append(f"\n{total} cases.\n")
    return "\n".join(lines)


def doc_messages(text: str) -> dict[str, str]:
    """{case id: message} of a rendered page."""
    out = {}
    for line in text.splitlines():
        if line.startswith("| `") and line.count("|") >= 5:
            cells = [c.strip() for c in line.strip().strip("|").split(" | ")]
            cid = cells[0].strip("`")
            msg = cells[2]
            out[cid] = msg[1:-1].replace("\\|", "|") if msg.startswith("`") else None
    return out


def run_all() -> dict[str, str]:
    """Runs every case that can run here; {case id: message}. Cases that need Scene.run to call the pre-flight take
    the message of their scene-API twin (the same check) until it does."""
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    twins = {"cli_dt_tiny": "dt_tiny", "cli_out_read_only": "out_read_only"}
    messages, failed = {}, []
    for c in CASES:
        if skip_reason(c):
            continue
        with tempfile.TemporaryDirectory(prefix="pdsim-errors-") as tmp:
            try:
                messages[c.id] = capture(c, Path(tmp))
            except AssertionError as exc:
                failed.append(f"{c.id}: {exc}")
    if failed:
        raise SystemExit("cases that do not fail as documented:\n" + "\n".join(failed))
    for cid, twin in twins.items():
        if cid not in messages and twin in messages:
            messages[cid] = messages[twin]
    return messages


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--check", action="store_true", help="exit 1 when docs/errors.md is out of date")
    args = p.parse_args(argv)
    old = doc_messages(DOC.read_text()) if DOC.exists() else {}
    messages = run_all()
    for cid, msg in old.items():  # keep what this machine cannot run (e.g. the CUDA case on a GPU machine)
        if cid not in messages and msg and any(c.id == cid for c in CASES):
            messages[cid] = msg
    text = render(messages)
    if args.check:
        current = DOC.read_text() if DOC.exists() else ""
        if current != text:
            print(f"{DOC} is out of date: run python tools/errors_catalogue.py", file=sys.stderr)
            return 1
        return 0
    DOC.write_text(text)
    print(f"wrote {DOC}: {len(CASES)} cases, {len(messages)} messages")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONWARNINGS", "ignore")
    sys.exit(main())
