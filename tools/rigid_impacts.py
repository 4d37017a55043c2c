"""Measurements of dynamic rigid bodies (pdsim/rigid.py) for docs/rigid_impacts.md: momentum exchange with free
peridynamic and FEM blocks (at the origin and 1 km from it), and a light ball against a heavy breakable body on the
ground (the figurine case) next to the same shot with a kinematic ball.

    python tools/rigid_impacts.py                 # prints the tables and rewrites docs/rigid_impacts.md
    python tools/rigid_impacts.py --no-write      # prints only

The scenes are those of tests/test_rigid_bodies.py (the tests assert the bounds; this prints the values).
"""

from __future__ import annotations

import argparse
import datetime
import math
import platform
from pathlib import Path

import numpy as np

import pdsim
from pdsim.rigid import BoxShape, SphereShape
from pdsim.run import advance_frame, method_contact

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "rigid_impacts.md"
STEEL = 7850.0


def _totals(body, solvers, point):
    p = body.linear_momentum() + sum(s.linear_momentum() for s in solvers)
    L = body.angular_momentum(point) + sum(s.angular_momentum(point) for s in solvers)
    e = body.kinetic_energy() + sum(s.kinetic_energy() for s in solvers)
    return p, L, e


def momentum_case(method: str, shape: str, shift) -> dict:
    """A 10 m/s steel body (sphere r 2 cm, box 4 cm, or a mesh icosphere r 2 cm) 2 cm off the centre line of a free
    elastic 10 cm block (2.4 kg, E 30 MPa) in space, 30 ms."""
    shift = np.asarray(shift, dtype=np.float64)
    scene = pdsim.Scene(gravity=(0.0, 0.0, 0.0), fps=1000)
    material = pdsim.Material(density=2400.0, youngs_modulus=3.0e7, poisson_ratio=0.2, name="elastic")
    if method == "pd":
        scene.add_peridynamic_body(pdsim.box((0.1, 0.1, 0.1), center=shift), material, 0.02, name="block")
    else:
        scene.add_fem_body(pdsim.box_tet_mesh((0.1, 0.1, 0.1), (3, 3, 3), center=shift), material, name="block")
    start = shift + np.array([-0.071 if shape == "sphere" else -0.075, 0.02, 0.0])
    if shape == "sphere":
        body = scene.add_rigid_body(SphereShape(0.02), density=STEEL, position=start, velocity=(10.0, 0.0, 0.0))
    elif shape == "box":
        body = scene.add_rigid_body(BoxShape((0.04,) * 3), density=STEEL, position=start, velocity=(10.0, 0.0, 0.0))
    else:
        mesh = pdsim.sphere(0.02, center=start, subdivisions=2)
        body = scene.add_rigid_body(mesh, density=STEEL, velocity=(10.0, 0.0, 0.0))
    solvers = scene.build_solvers(device="cpu")
    point = shift + np.array([0.0, -0.05, 0.03])
    p0, L0, e0 = _totals(body, solvers, point)
    body_p0 = body.linear_momentum()
    dt = 0.7 * min(s.stable_time_step() for s in solvers)
    depth = 0.0  # deepest penetration of a sphere body by a particle (spheres of radius h/2) [m]
    coupling = method_contact(scene, solvers)
    for _ in range(math.ceil(0.03 / dt)):
        advance_frame(solvers, dt, 1, coupling)
        if shape == "sphere" and method == "pd":
            gap = np.linalg.norm(solvers[0].positions() - body.state_values()["position"], axis=1) - 0.02 - 0.01
            depth = max(depth, -float(gap.min()))
    p1, L1, e1 = _totals(body, solvers, point)
    block = sum(s.linear_momentum() for s in solvers)
    return {
        "case": f"{shape} -> {method} block" + (" at 1 km" if np.any(shift) else ""),
        "dp": np.linalg.norm(p1 - p0) / np.linalg.norm(p0),
        "dL": np.linalg.norm(L1 - L0) / np.linalg.norm(L0),
        "exchange": np.linalg.norm(body.linear_momentum() - body_p0 + block) / np.linalg.norm(p0),
        "v": body.state_values()["velocity"][0],
        "energy": e1 / e0,
        "depth": depth,
        "travel": 10.0 * dt,
    }


FIGURINE_BALL_MASS, FIGURINE_BALL_SPEED, FIGURINE_BODY_MASS = 0.2, 15.0, 10.0  # [kg], [m/s], [kg]


def figurine_run(kinematic: bool, material: pdsim.Material | None = None):
    """A FIGURINE_BALL_MASS steel ball at FIGURINE_BALL_SPEED into a resting FIGURINE_BODY_MASS breakable cube
    (``material``, default the concrete preset; h = edge / 4) on the ground, 10 ms: a dynamic ball
    (``add_rigid_body``) or, with ``kinematic``, a scripted one of infinite mass (SphereProjectile). Returns the
    peridynamic solver and the cube's edge [m]."""
    m_ball, v0 = FIGURINE_BALL_MASS, FIGURINE_BALL_SPEED
    radius = (m_ball / (STEEL * 4.0 / 3.0 * math.pi)) ** (1.0 / 3.0)
    material = pdsim.presets.concrete() if material is None else material
    edge = (FIGURINE_BODY_MASS / material.density) ** (1.0 / 3.0)
    scene = pdsim.Scene(fps=1000)
    scene.add_ground_plane()
    scene.add_peridynamic_body(pdsim.box((edge,) * 3, center=(0.0, 0.0, 0.5 * edge)), material, edge / 4.0, name="b")
    start = (-0.5 * edge - radius - 0.002, 0.0, 0.5 * edge)
    if kinematic:
        scene.add_collider(pdsim.SphereProjectile(radius, start, velocity=(v0, 0.0, 0.0)))
    else:
        scene.add_rigid_body(SphereShape(radius), mass=m_ball, position=start, velocity=(v0, 0.0, 0.0))
    solvers = scene.build_solvers(device="cpu")
    (solver,) = solvers
    dt = 0.7 * solver.stable_time_step()
    advance_frame(solvers, dt, math.ceil(0.01 / dt), method_contact(scene, solvers))
    return solver, edge


def figurine_case(kinematic: bool) -> dict:
    """:func:`figurine_run`'s figures: the cube's centre-of-mass speed against the elastic bound, the fragment count
    and the fastest fragment's speed over its energy bound."""
    m_ball, v0, g = FIGURINE_BALL_MASS, FIGURINE_BALL_SPEED, 9.81
    solver, edge = figurine_run(kinematic)
    mass, v = solver.masses(), solver.velocities()
    M = float(mass.sum())
    com = mass @ v / M
    ids = solver.fragment_ids()
    worst = 0.0
    for f in np.unique(ids):
        sel = ids == f
        m = float(mass[sel].sum())
        speed = float(np.linalg.norm(mass[sel] @ v[sel] / m))
        worst = max(worst, speed / math.sqrt((m_ball * v0**2 + 2.0 * m * g * edge) / m))
    return {
        "case": "kinematic ball (SphereProjectile)" if kinematic else "rigid ball (add_rigid_body)",
        "com_x": com[0],
        "bound": 2.0 * m_ball * v0 / (m_ball + M),
        "fragments": len(np.unique(ids)),
        "worst": worst,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-write", action="store_true", help="print the tables without rewriting the page")
    args = parser.parse_args()
    rows = [momentum_case(m, "sphere", s) for m in ("pd", "fem") for s in ((0, 0, 0), (1000.0, 0, 0))]
    rows += [momentum_case("pd", shape, (0, 0, 0)) for shape in ("box", "mesh")]
    lines = [
        "| case | linear momentum error | angular momentum error | exchange error | body's final v_x [m/s] | "
        "kinetic energy after / before |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['case']} | {r['dp']:.1e} | {r['dL']:.1e} | {r['exchange']:.1e} | {r['v']:.3f} | {r['energy']:.3f} |"
        )
    momentum = "\n".join(lines)
    depth = rows[0]["depth"]
    figs = [figurine_case(False), figurine_case(True)]
    lines = [
        "| ball | block's centre of mass v_x [m/s] | bound 2 m v0 / (m + M) [m/s] | fragments | "
        "largest fragment speed / its energy bound |",
        "|---|---|---|---|---|",
    ]
    for r in figs:
        lines.append(f"| {r['case']} | {r['com_x']:.3f} | {r['bound']:.3f} | {r['fragments']} | {r['worst']:.3f} |")
    figurine = "\n".join(lines)
    print(momentum, "\n", figurine, sep="\n")
    if args.no_write:
        return
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    machine = f"{platform.machine()}, {platform.system()}, Python {platform.python_version()}, Warp CPU"
    DOC.write_text(
        "# Dynamic rigid bodies: measured impacts\n\n"
        f"Written by `python tools/rigid_impacts.py` on {stamp} ({machine}). tests/test_rigid_bodies.py asserts the "
        "bounds on the same scenes.\n\n"
        "## Momentum exchange with a free block in space\n\n"
        "A steel body at 10 m/s, 2 cm off the centre line of a free elastic 10 cm block (2.4 kg, E 30 MPa, h 2 cm "
        "or 3 x 3 x 3 cells of 6 tetrahedra), 30 ms at 0.7 x the stable step. Errors are relative to the initial "
        "totals (angular momentum about a fixed point off the line of the impact); the exchange error compares the "
        "body's change of momentum with the block's. The contact is inelastic, so kinetic energy only falls (the "
        "block's strain energy is not counted).\n\n"
        f"{momentum}\n\n"
        f"The deepest penetration of the sphere by a particle (sphere -> pd block, every step): {depth * 1e3:.2f} mm, "
        f"{depth / 0.01:.2f} particle radii; the ball travels {rows[0]['travel'] * 1e3:.2f} mm per step.\n\n"
        "## The figurine case: a light ball against a heavy breakable body\n\n"
        "A 0.2 kg steel ball at v0 = 15 m/s into a resting 10 kg breakable concrete cube (pdsim.presets.concrete, "
        "h = edge / 4) on the ground, 10 ms. No elastic collision gives the block's centre more than "
        "2 m v0 / (m + M); a fragment of mass m_f cannot be faster than sqrt((m v0^2 + 2 m_f g H) / m_f) (the ball's "
        "energy plus the fall over the block's height H). A kinematic ball has infinite mass and keeps pushing.\n\n"
        f"{figurine}\n"
    )
    print(f"wrote {DOC}")


if __name__ == "__main__":
    main()
