"""Lattice case a of dell'Erba 2018 (docs/lattice.md): tensile test with release (Table 1): 10x10 square, Figure 3's
8-neighbour (Chebyshev) shell, left column clamped, right column pulled at 1.2 units/step (case a's text; Table 1
says 0.35: ``case_a_scene(speed=0.35)``) for 10 steps then released into followers, 401 steps; tracks the central
particle j = 67 (Figures 5, 6, 8, 9). The rows next to the frame lag the middle ones.

Parameters: scenes/lattice_paper.py and docs/lattice.md. Writes the USD cache and the PNG figures (PE1 and PE2 contour
plots at the paper's steps, trajectories of the tracked particles).

Run:  python scenes/lattice_case_a.py [--out lattice_case_a.usdc] [--plots lattice_case_a_plots]
  or  pdsim run scenes/lattice_case_a.py   (cache only)
"""

from lattice_paper import case_a_scene as build_scene

PREVIEW = {}  # tools/make_gallery.py and tests/test_gallery.py: the case is small enough as it is

if __name__ == "__main__":
    from lattice_paper import run_lattice_scene

    raise SystemExit(run_lattice_scene(build_scene, frames=[1, 10, 20, 401], pe2_frames=[2, 10]))
