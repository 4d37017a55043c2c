"""Contact between the pieces of a cracking FEM slab: how deep a vertex of one piece gets inside another, frame by
frame, with contact on and off.

    python tools/fem_piece_contact.py [--speed 1.5] [--frames 12] [--ball]

A 16 x 4 x 2 cm slab (8 x 2 x 1 cubes of six tetrahedra, E = 1 MPa, tensile strength 30 kPa) lies on the ground
(friction 0.5, gravity) and a kinematic sphere of radius 2 cm comes down on its middle at ``--speed`` m/s (with
``--ball``: a rigid steel ball of radius 1.5 cm, 0.11 kg, that the pieces push back; tests/test_fem_contact.py runs
it at 3 m/s). A kinematic sphere keeps going whatever it meets: it wedges into the slab and squeezes the pieces into
each other and the ground, which no contact can resolve, so its frames show the contact's floor fighting it. Each frame
(1/240 s) the tool prints the piece count (vertex-connected pieces of the contact mesh, SolverFem.contact_pieces) and
the deepest a surface vertex of one piece lies inside another piece's closed surface (trimesh's signed distance),
for contact on (MethodContact between FEM surfaces, the default) and off (Scene.enable_contact(False)).

    python tools/fem_piece_contact.py --ball --speed 3 --frames 16 --classify

follows every surface vertex step by step (contact on) and says, for each frame's deepest vertex, where its depth comes
from: ``split`` (born at a split: it was inside the other piece in the first step after the split that made the two
pieces, before contact between them had acted), ``load`` (it entered while the pieces were separate and the nearest face
of another piece, the pair the contact kernel takes, is a face of the piece it is inside: the contact saw it and gave
way), ``third piece`` (the nearest face of another piece belongs to a third piece, one the vertex is outside: the
contact kernel, which takes the nearest face of another piece, finds no pair there) or ``beyond band`` (deeper than the
contact's band: the kernel finds no pair); ``collider`` is added where a collider (the ground, the ball) has moved the
vertex or the points of that face since it entered: colliders move the points they push after the drift, each along its
own normal, with no regard for the pieces' contact. The depth at entry and the steps since entry are printed beside it,
and the deepest of the vertices that no collider has moved since they entered. ``--time`` prints the least wall time per
step of the shot with contact on over three runs.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import trimesh

import pdsim
from pdsim.run import advance_frame, method_contact

SOFT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)


def deepest_inside(solver) -> tuple[int, float]:
    """(piece count, deepest [m] a contact-mesh vertex of one piece lies inside another piece)."""
    x = solver.positions()
    ids, faces, _ = solver.contact_mesh()
    vertex_label, face_label = (a.numpy() for a in solver.contact_pieces())
    ids, faces = ids.numpy(), faces.numpy().reshape(-1, 3)
    labels = np.unique(face_label)
    depth = 0.0
    for label in labels if len(labels) > 1 else ():
        mesh = trimesh.Trimesh(x[ids], faces[face_label == label], process=False)
        others = ids[vertex_label != label]
        depth = max(depth, float(trimesh.proximity.signed_distance(mesh, x[others]).max()))
    return len(labels), depth


def inside_depths(solver):
    """Per point of the solver: piece label (-1 off the contact mesh), the deepest [m] it lies inside another piece
    (-inf off the contact mesh or inside none), the label of that piece (-1 none), whether the nearest face of
    another piece belongs to that piece (trimesh's closest point; the pair the contact kernel takes), and the solver
    points of that nearest face (int [n, 3], -1 where none)."""
    x = solver.positions()
    ids, faces, _ = solver.contact_mesh()
    vertex_label, face_label = (a.numpy() for a in solver.contact_pieces())
    ids, faces = ids.numpy(), faces.numpy().reshape(-1, 3)
    n = x.shape[0]
    label = np.full(n, -1, dtype=np.int64)
    label[ids] = vertex_label
    depth = np.full(n, -np.inf)
    inside = np.full(n, -1, dtype=np.int64)
    nearest_ok = np.zeros(n, dtype=bool)
    nearest_face = np.full((n, 3), -1, dtype=np.int64)
    labels = np.unique(face_label)
    if len(labels) < 2:
        return label, depth, inside, nearest_ok, nearest_face
    for piece in labels:
        mesh = trimesh.Trimesh(x[ids], faces[face_label == piece], process=False)
        others = ids[vertex_label != piece]
        d = trimesh.proximity.signed_distance(mesh, x[others])
        deeper = d > depth[others]
        depth[others[deeper]] = d[deeper]
        inside[others[deeper]] = piece
    for piece in labels:
        own = ids[(vertex_label == piece) & (depth[ids] > 0.0)]
        if len(own) == 0:
            continue
        foreign = face_label != piece
        mesh = trimesh.Trimesh(x[ids], faces[foreign], process=False)
        _, _, tri = trimesh.proximity.closest_point(mesh, x[own])
        nearest_ok[own] = face_label[foreign][tri] == inside[own]
        nearest_face[own] = ids[faces[foreign][tri]]
    return label, depth, inside, nearest_ok, nearest_face


class _Recorder:
    """Wraps a MethodContact: before each step's contact (positions at the step's end, after any split of the step
    before) it records every vertex's depth inside other pieces (inside_depths) and, per vertex, the step it last
    entered another piece, whether it entered at a split, its depth then, and whether a collider (the ground, a
    projectile, a rigid body: the solver's apply_colliders, wrapped to see its moves) has moved the vertex or the
    nearest face's points since then."""

    def __init__(self, coupling, solver):
        self.coupling, self.solver = coupling, solver
        self.step = 0
        self.label = None
        self.entry = {}  # point -> (step, born at split, depth at entry [m])
        self.collided = {}  # point -> a collider moved it or its nearest face since it entered
        self.last = None
        self.moved = np.zeros(0, dtype=bool)
        colliders = solver.apply_colliders

        def apply_colliders(time, dt):
            before = solver.positions()
            colliders(time, dt)
            self.moved = np.any(solver.positions() != before, axis=1)

        solver.apply_colliders = apply_colliders

    def apply(self, dt: float) -> None:
        label, depth, inside, nearest_ok, nearest_face = inside_depths(self.solver)
        previous = self.label
        for i in np.flatnonzero(depth > 0.0):
            was_inside = self.last is not None and i < len(self.last[1]) and self.last[1][i] > 0.0
            if not was_inside:
                same_before = False
                if previous is not None:
                    members = np.flatnonzero(label == inside[i])
                    members = members[members < len(previous)]
                    same_before = i < len(previous) and bool(np.any(previous[members] == previous[i]))
                self.entry[int(i)] = (self.step, same_before, float(depth[i]))
                self.collided[int(i)] = False
            elif len(self.moved) == len(depth):
                self.collided[int(i)] |= bool(self.moved[i] or np.any(self.moved[nearest_face[i]]))
        self.label = label
        self.last = (label, depth, inside, nearest_ok)
        self.step += 1
        self.coupling.apply(dt)

    def end_step(self, dt: float) -> None:
        self.coupling.end_step(dt)

    def deepest(self, band: float) -> tuple[float, str, float, int, float]:
        """(depth [m], class, depth at entry [m], steps since entry) of the deepest vertex at the last record, and
        the deepest [m] of the vertices that no collider has moved (nor their nearest face's points) since they
        entered."""
        _, depth, _, nearest_ok = self.last
        inside = np.flatnonzero(depth > 0.0)
        free = [float(depth[i]) for i in inside if not self.collided[int(i)]]
        free_depth = max(free, default=0.0)
        if len(inside) == 0:
            return 0.0, "-", 0.0, 0, free_depth
        i = int(inside[np.argmax(depth[inside])])
        step, at_split, depth0 = self.entry[i]
        kind = "split" if at_split else "load"
        if depth[i] > band:
            kind = "beyond band"
        elif not nearest_ok[i]:
            kind = "third piece"
        kind += ", collider" if self.collided[i] else ""
        return float(depth[i]), kind, depth0, self.step - step, free_depth


def classify(speed: float, frames: int, ball: bool = True, device: str = "cpu") -> list[tuple]:
    """Per frame, the deepest vertex's (depth [m], class, depth at entry [m], steps since entry) and the deepest [m]
    of the vertices no collider has moved since they entered (module docstring)."""
    solver, coupling, dt, substeps = _scene(speed, True, ball, device)
    recorder = _Recorder(coupling, solver)
    band = solver.contact_skin()[1]
    rows = []
    for _ in range(frames):
        advance_frame([solver], dt, substeps, recorder)
        rows.append(recorder.deepest(band))
    return rows


def _scene(speed: float, contact: bool, ball: bool, device: str):
    """(solver, method contact, step [s], steps per frame) of the slab shot (module docstring)."""
    scene = pdsim.Scene(gravity=(0.0, 0.0, -9.81))
    if not contact:
        scene.enable_contact(False)
    scene.add_ground_plane(height=0.0, friction=0.5)
    mesh = pdsim.box_tet_mesh((0.16, 0.04, 0.02), (8, 2, 1), center=(0.0, 0.0, 0.011))
    scene.add_body(pdsim.FemBody(mesh, SOFT, name="slab", tensile_strength=3.0e4))
    if ball:
        scene.add_rigid_body(pdsim.SphereShape(0.015), density=7850.0, position=(0.0, 0.0, 0.04),
                             velocity=(0.0, 0.0, -speed), name="ball")  # fmt: skip
    else:
        scene.add_collider(pdsim.SphereProjectile(0.02, center=(0.0, 0.0, 0.045), velocity=(0.0, 0.0, -speed)))
    (solver,) = scene.build_solvers(device=device)
    coupling = method_contact(scene, [solver])
    dt = scene.time_step_safety * solver.stable_time_step()
    return solver, coupling, dt, round(1.0 / 240.0 / dt)


def run(speed: float, frames: int, contact: bool, ball: bool = False, device: str = "cpu") -> list[tuple[int, float]]:
    """(piece count, deepest inside [m]) at the end of each frame (module docstring)."""
    solver, coupling, dt, substeps = _scene(speed, contact, ball, device)
    rows = []
    for _ in range(frames):
        advance_frame([solver], dt, substeps, coupling)
        rows.append(deepest_inside(solver))
    return rows


def step_time(speed: float, frames: int, ball: bool, repeats: int = 3, device: str = "cpu") -> float:
    """The least wall time [s] per step of the shot with contact on, over ``repeats`` runs of ``frames`` frames (the
    kernels compiled and loaded by a first frame before)."""
    solver, coupling, dt, substeps = _scene(speed, True, ball, device)
    advance_frame([solver], dt, substeps, coupling)
    best = float("inf")
    for _ in range(repeats):
        solver, coupling, dt, substeps = _scene(speed, True, ball, device)
        start = time.perf_counter()
        for _ in range(frames):
            advance_frame([solver], dt, substeps, coupling)
        best = min(best, (time.perf_counter() - start) / (frames * substeps))
    return best


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speed", type=float, default=1.5, help="the sphere's speed [m/s]")
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--ball", action="store_true", help="a rigid ball with mass instead of the kinematic sphere")
    parser.add_argument("--classify", action="store_true", help="where each frame's deepest vertex comes from")
    parser.add_argument("--time", action="store_true", help="the least wall time per step, contact on (3 runs)")
    args = parser.parse_args(argv)
    if args.time:
        print(f"{step_time(args.speed, args.frames, args.ball) * 1e3:.3f} ms per step")
        return
    if args.classify:
        header = "| frame | deepest inside [mm] | class | depth at entry [mm] | steps since entry |"
        print(header + " deepest, no collider [mm] |")
        print("|---|---|---|---|---|---|")
        for i, (d, kind, d0, steps, free) in enumerate(classify(args.speed, args.frames, args.ball)):
            print(f"| {i + 1} | {d * 1e3:.2f} | {kind} | {d0 * 1e3:.2f} | {steps} | {free * 1e3:.2f} |")
        return
    on, off = (run(args.speed, args.frames, contact, args.ball) for contact in (True, False))
    print("| frame | pieces (on) | deepest inside, contact on [mm] | pieces (off) | deepest inside, contact off [mm] |")
    print("|---|---|---|---|---|")
    for i, ((n_on, d_on), (n_off, d_off)) in enumerate(zip(on, off, strict=True)):
        print(f"| {i + 1} | {n_on} | {d_on * 1e3:.2f} | {n_off} | {d_off * 1e3:.2f} |")


if __name__ == "__main__":
    main()
