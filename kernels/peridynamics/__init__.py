"""Warp kernels of the peridynamics method."""
