"""Output: the USD animation-cache writer (the only part of pdsim that imports pxr)."""

from .usd import MeshHandle, PointsHandle, UsdCache, validate_usd

__all__ = ["MeshHandle", "PointsHandle", "UsdCache", "validate_usd"]
