"""Output: the method-neutral views of a solver's state (``views``, free of pxr) and the USD animation-cache writer
(``writer``, ``usd`` and its ``usd_*`` modules, which import pxr). Import the modules themselves, e.g.
``from pdsim.output.usd import UsdCache``: this package imports none of them, so the solvers' import of ``views``
does not load pxr."""
