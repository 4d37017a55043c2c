"""The CI subset of the stress sweeps (tools/stress.py --quick; the full sweep writes the stability map of
docs/stability.md).

Every method (peridynamics, FEM, lattice) through ``Scene.run`` and its watchdog, in tiny scenes (a few hundred
particles, elements or lattice points): time step 1x to 3x automatic, Young's modulus 1e3 to 1e11 Pa, Poisson's ratio
0.49, impacts at 10 and 200 m/s, compression towards 30 % of the height, a 360 degree twist, FEM slivers, a projectile
at 200 m/s, loads and kicks, and seeded random scenes (hypothesis). Pass: no run is silently wrong (no NaN or Inf in
the cache; energy E(t) - E(0) <= W(t) + 30 % (55 % above the automatic step) of |E(0)| + W(t) + |U_g(t)| at every
frame end, W the work of loads, boundary conditions, kicks and moving colliders, U_g the gravity potential) and none
fails otherwise; where a run diverges it is caught with the frames before it in the cache.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import sys
import tempfile

import pytest

_TOOL = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "tools", "stress.py")


def _load_tool():
    """tools/stress.py as the module ``pdsim_stress_tool`` (once; the random-scene tests share it)."""
    if "pdsim_stress_tool" not in sys.modules:
        spec = importlib.util.spec_from_file_location("pdsim_stress_tool", _TOOL)
        module = importlib.util.module_from_spec(spec)
        sys.modules["pdsim_stress_tool"] = module  # dataclasses look their module up
        spec.loader.exec_module(module)
    return sys.modules["pdsim_stress_tool"]


stress = _load_tool()
CASES = stress.cases(quick=True)


@pytest.fixture(scope="module")
def folder():
    path = tempfile.mkdtemp(prefix="pdsim_stress_test_")
    yield path
    shutil.rmtree(path, ignore_errors=True)


@pytest.mark.parametrize("case", CASES, ids=[c.label for c in CASES])
def test_stress_case(case, folder):
    """Stable or caught, never silently wrong; the expected outcome where the physics fixes it."""
    rec = stress.run_case(case, folder)
    assert rec.outcome in ("stable", "caught"), f"{rec.outcome}: {rec.message}"
    if rec.outcome == "caught":
        assert "likely cause: " in rec.message, rec.message
        assert rec.last_frame >= 0  # the cache opens with the frames before the failure (checked finite)
    if case.group == "map_dt" and case.method == "peridynamics" and case.params["dt_factor"] >= 3.0:
        assert rec.outcome == "caught" and "likely cause: the time step" in rec.message  # breakable: fracture hides it
    if case.group == "map_dt" and case.params["dt_factor"] == 1.0 and case.params["E"] >= 1.0e7:
        assert rec.outcome == "stable"
    if case.group in ("loads", "kick", "projectile", "twist", "nu", "slivers"):
        assert rec.outcome == "stable", rec.message
    if case.group == "twist" and case.method == "peridynamics":
        assert rec.extra["twist_deg"] >= 360.0
    if case.group == "compress" and rec.outcome == "caught":
        assert "likely cause: large deformation" in rec.message
