"""Warp kernels of pdsim, installed as ``pdsim.kernels``. Only ``@wp.kernel`` / ``@wp.func`` code lives here."""
