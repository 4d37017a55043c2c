"""Seeded random scenes (tools/stress.py random_case) drawn by hypothesis: material (E 1e3 .. 1e11 Pa, nu 0 .. 0.49),
fracture on or off, impact speed 0 .. 200 m/s, gravity, time-step factor 0.1 .. 3, peridynamics or FEM. The examples
are derandomized (the same seeds on every run; hypothesis prints the failing seed) plus the explicit examples below.
Pass: stable or caught, never silently wrong. Seed 971 (found by hypothesis: an unbreakable block at 2.04 x the
automatic step whose measured energy sits 15 % above E(0), stable over 1000 steps, which a 10 % audit had called
silently wrong) is kept as an explicit example."""

from __future__ import annotations

import importlib.util
import os
import shutil
import sys
import tempfile

import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import example, given, note, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_TOOL = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "tools", "stress.py")
if "pdsim_stress_tool" not in sys.modules:
    _spec = importlib.util.spec_from_file_location("pdsim_stress_tool", _TOOL)
    sys.modules["pdsim_stress_tool"] = importlib.util.module_from_spec(_spec)  # dataclasses look their module up
    _spec.loader.exec_module(sys.modules["pdsim_stress_tool"])
stress = sys.modules["pdsim_stress_tool"]


@settings(max_examples=3, deadline=None, derandomize=True, database=None)
@given(seed=st.integers(min_value=0, max_value=2**31 - 1))
@example(seed=5)
@example(seed=971)  # PD at 2.04x the automatic step: stable, its measured energy 15 % above E(0) (Verlet's bias)
def test_random_scene_is_stable_or_caught(seed):
    case = stress.random_case(seed, max_steps_factor=1.0)
    note(f"seed {seed}: {case.label}")
    folder = tempfile.mkdtemp(prefix="pdsim_random_")
    try:
        rec = stress.run_case(case, folder)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    note(f"outcome {rec.outcome}, audit {rec.audit:+.3f}: {rec.message}")
    assert rec.outcome in ("stable", "caught"), f"seed {seed}: {rec.outcome}: {rec.message}"
