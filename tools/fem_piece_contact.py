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
"""

from __future__ import annotations

import argparse

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


def run(speed: float, frames: int, contact: bool, ball: bool = False, device: str = "cpu") -> list[tuple[int, float]]:
    """(piece count, deepest inside [m]) at the end of each frame (module docstring)."""
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
    rows = []
    for _ in range(frames):
        advance_frame([solver], dt, round(1.0 / 240.0 / dt), coupling)
        rows.append(deepest_inside(solver))
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speed", type=float, default=1.5, help="the sphere's speed [m/s]")
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--ball", action="store_true", help="a rigid ball with mass instead of the kinematic sphere")
    args = parser.parse_args(argv)
    on, off = (run(args.speed, args.frames, contact, args.ball) for contact in (True, False))
    print("| frame | pieces (on) | deepest inside, contact on [mm] | pieces (off) | deepest inside, contact off [mm] |")
    print("|---|---|---|---|---|")
    for i, ((n_on, d_on), (n_off, d_off)) in enumerate(zip(on, off, strict=True)):
        print(f"| {i + 1} | {n_on} | {d_on * 1e3:.2f} | {n_off} | {d_off * 1e3:.2f} |")


if __name__ == "__main__":
    main()
