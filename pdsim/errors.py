"""Error types raised by pdsim.

User mistakes (bad parameters, unusable meshes, unstable time steps) raise subclasses of :class:`PdsimError`; the CLI
prints their message on one line and exits non-zero without a traceback.
"""

from __future__ import annotations


class PdsimError(Exception):
    """Base class for errors caused by the scene or its input, not by a defect in pdsim."""


class ParameterError(PdsimError, ValueError):
    """A parameter is outside its allowed range."""

    def __init__(self, field: str, value, allowed: str):
        self.field = field
        self.value = value
        self.allowed = allowed
        super().__init__(f"{field}={value!r} is invalid: allowed {allowed}")


class GeometryError(PdsimError, ValueError):
    """A mesh or shape cannot be turned into a solid body."""


class InstabilityError(PdsimError, RuntimeError):
    """The explicit integration diverged (time step too large or a blown-up state)."""


class FeatureNotAvailableError(PdsimError, NotImplementedError):
    """A requested feature is not implemented in this version of pdsim."""


class OutputWriteError(PdsimError, RuntimeError):
    """Writing the cache or a checkpoint failed during a run (disk full, folder turned read-only); the message names
    the path, the error, the free space and where the finished frames are."""
