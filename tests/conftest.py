"""Shared test set-up: Warp on the CPU backend, quiet."""

import pytest


@pytest.fixture(scope="session", autouse=True)
def _warp_quiet():
    import warp as wp

    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    wp.init()


@pytest.fixture
def device():
    """Tests run on the CPU backend (CI has no GPU)."""
    return "cpu"
