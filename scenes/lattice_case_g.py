"""Lattice case g of dell'Erba 2018 (docs/lattice.md): the frame rule: hexagonal fracture, second gradient, averaging
frame rule against the single-follower rule (0.35 units/step, thresholds 2.0 / 2.5 units, as case f); with averaging two
frame points stay between the pieces (Figure 22).

Parameters: scenes/lattice_paper.py and docs/lattice.md. Writes the USD cache and the PNG figures (PE1 and PE2 contour
plots at the paper's steps, trajectories of the tracked particles).

Run:  python scenes/lattice_case_g.py [--out lattice_case_g.usdc] [--plots lattice_case_g_plots]
  or  pdsim run scenes/lattice_case_g.py   (cache only)
"""

from lattice_paper import case_g_scene as build_scene

PREVIEW = {}  # tools/make_gallery.py and tests/test_gallery.py: the case is small enough as it is

if __name__ == "__main__":
    from lattice_paper import run_lattice_scene

    raise SystemExit(run_lattice_scene(build_scene, frames=[1, 8, 9, 100], pe2_frames=None))
