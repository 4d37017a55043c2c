"""Lattice case e of dell'Erba 2018 (docs/lattice.md): Saint-Venant's principle: four internal leaders of a 20x20 square
diverge along the bisectors at 0.35 units/step (Table 1) for 10 steps; remote particles stay at rest (Figure 17,
step 9).

Parameters: scenes/lattice_paper.py and docs/lattice.md. Writes the USD cache and the PNG figures (PE1 and PE2 contour
plots at the paper's steps, trajectories of the tracked particles).

Run:  python scenes/lattice_case_e.py [--out lattice_case_e.usdc] [--plots lattice_case_e_plots]
  or  pdsim run scenes/lattice_case_e.py   (cache only)
"""

from lattice_paper import case_e_scene as build_scene

PREVIEW = {}  # tools/make_gallery.py and tests/test_gallery.py: the case is small enough as it is

if __name__ == "__main__":
    from lattice_paper import run_lattice_scene

    raise SystemExit(run_lattice_scene(build_scene, frames=[1, 5, 9, 40], pe2_frames=[5, 9]))
