"""Shared test set-up: Warp quiet; tests that take the ``device`` fixture run on the CPU always and on CUDA when
present (CI has no GPU, so there they run on the CPU backend only)."""

import os
import sys

import pytest

# scene scripts and tools are scripts, not package modules: make them importable by the tests
_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for _folder in ("scenes", "tools"):
    if os.path.join(_ROOT, _folder) not in sys.path:
        sys.path.insert(0, os.path.join(_ROOT, _folder))


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
