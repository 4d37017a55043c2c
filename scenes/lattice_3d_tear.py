"""3D lattice scene: a round dog-bone bar (length 24, radius 4, neck radius 1.8 units) filled with a simple cubic
lattice, clamped at one grip and pulled slowly at the other along x (0.005 units/step for 1200 steps); links longer
than 1.3 units are lost, so it necks and tears in the middle (about step 800). 100 frames of 20 steps. Writes the USD
cache (primvars kind, pe1, pe1_intact, pe2, displacement, broken_links, fragment).

Run:  python scenes/lattice_3d_tear.py [--out lattice_3d_tear.usdc]   or   pdsim run scenes/lattice_3d_tear.py
"""

from lattice_paper import tear_3d_scene as build_scene

# tools/make_gallery.py and tests/test_gallery.py: the same 2000 steps in 50 frames of 40 steps
PREVIEW = {"frames": 50, "steps_per_frame": 40}

if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)
