"""Warp kernels of the lattice method."""
