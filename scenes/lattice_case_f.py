"""Lattice case f of dell'Erba 2018 (docs/lattice.md): the lattice decides the fracture: hexagonal 15x17 specimen (first
and second gradient) beside the square one, averaging frame rule, Table 1's 0.35 units/step and thresholds 2.0 / 2.5
units, 400 steps; the hexagonal tracked particle j = 133 rebounds (Figures 18-21).

Parameters: scenes/lattice_paper.py and docs/lattice.md. Writes the USD cache and the PNG figures (PE1 and PE2 contour
plots at the paper's steps, trajectories of the tracked particles).

Run:  python scenes/lattice_case_f.py [--out lattice_case_f.usdc] [--plots lattice_case_f_plots]
  or  pdsim run scenes/lattice_case_f.py   (cache only)
"""

from lattice_paper import case_f_scene as build_scene

PREVIEW = {}  # tools/make_gallery.py and tests/test_gallery.py: the case is small enough as it is

if __name__ == "__main__":
    from lattice_paper import run_lattice_scene

    raise SystemExit(run_lattice_scene(build_scene, frames=[1, 7, 8, 9, 10, 12, 27, 400], pe2_frames=[8, 9]))
