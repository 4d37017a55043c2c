"""Lattice case d of dell'Erba 2018 (docs/lattice.md): simple fracture: square 15x13 specimen (Figure 3's Chebyshev
shells) pulled at 1.2 units/step for 10 steps, links lost beyond 4.0 / 6.0 units (shell 1 / 2), fictitious points at the
rest offset; first and second gradient; tracks j = 103, which rebounds after the crack with the second gradient only
(Figures 14, 15, 16). Table 1's reading: ``case_d_scene(metric="coordination", speed=TABLE1_SPEED,
distances=TABLE1_DISTANCES)``.

Parameters: scenes/lattice_paper.py and docs/lattice.md. Writes the USD cache and the PNG figures (PE1 and PE2 contour
plots at the paper's steps, trajectories of the tracked particles).

Run:  python scenes/lattice_case_d.py [--out lattice_case_d.usdc] [--plots lattice_case_d_plots]
  or  pdsim run scenes/lattice_case_d.py   (cache only)
"""

from lattice_paper import case_d_scene as build_scene

PREVIEW = {}  # tools/make_gallery.py and tests/test_gallery.py: the case is small enough as it is

if __name__ == "__main__":
    from lattice_paper import run_lattice_scene

    raise SystemExit(run_lattice_scene(build_scene, frames=[1, 5, 6, 7, 8, 100], pe2_frames=[5, 6]))
