"""Shared test set-up: Warp quiet; tests that take the ``device`` fixture run on the CPU always and on CUDA when
present (CI has no GPU, so there they run on the CPU backend only)."""

import pytest


def _devices():
    import warp as wp

    return ["cpu"] + (["cuda"] if wp.get_cuda_device_count() > 0 else [])


@pytest.fixture(scope="session", autouse=True)
def _warp_quiet():
    import warp as wp

    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    wp.init()


def pytest_generate_tests(metafunc):
    if "device" in metafunc.fixturenames:
        metafunc.parametrize("device", _devices())
