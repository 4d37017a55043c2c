"""Lattice case c of dell'Erba 2018 (docs/lattice.md): the importance of the gradient: case b with second-gradient
neighbours and a two-layer frame, beside case b's specimen; j = 67 contracts less (Figures 12, 13).

Parameters: scenes/lattice_paper.py and docs/lattice.md. Writes the USD cache and the PNG figures (PE1 and PE2 contour
plots at the paper's steps, trajectories of the tracked particles).

Run:  python scenes/lattice_case_c.py [--out lattice_case_c.usdc] [--plots lattice_case_c_plots]
  or  pdsim run scenes/lattice_case_c.py   (cache only)
"""

from lattice_paper import case_c_scene as build_scene

PREVIEW = {}  # tools/make_gallery.py and tests/test_gallery.py: the case is small enough as it is

if __name__ == "__main__":
    from lattice_paper import run_lattice_scene

    raise SystemExit(run_lattice_scene(build_scene, frames=[1, 10, 20, 100], pe2_frames=None))
