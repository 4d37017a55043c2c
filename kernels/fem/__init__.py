"""Warp kernels of the fem method."""
