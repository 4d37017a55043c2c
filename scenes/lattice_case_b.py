"""Lattice case b of dell'Erba 2018 (docs/lattice.md): the Poisson effect: case a without release (leaders stop after 10
steps at 1.2 units/step), 100 steps, mixed-coordinate rule K = 0.01 /unit; the central particle j = 67, above the
axis, moves down (Figures 10, 11).

Parameters: scenes/lattice_paper.py and docs/lattice.md. Writes the USD cache and the PNG figures (PE1 and PE2 contour
plots at the paper's steps, trajectories of the tracked particles).

Run:  python scenes/lattice_case_b.py [--out lattice_case_b.usdc] [--plots lattice_case_b_plots]
  or  pdsim run scenes/lattice_case_b.py   (cache only)
"""

from lattice_paper import case_b_scene as build_scene

PREVIEW = {}  # tools/make_gallery.py and tests/test_gallery.py: the case is small enough as it is

if __name__ == "__main__":
    from lattice_paper import run_lattice_scene

    raise SystemExit(run_lattice_scene(build_scene, frames=[1, 10, 20, 100], pe2_frames=None))
