"""NVIDIA's Omniverse asset validator (``omniverse-asset-validator``, pure Python) on a peridynamic and an FEM cache:
the findings left are the known ones explained in docs/cache_format.md, nothing else. Skipped when the validator is
not installed (it is in the ``test`` extra)."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

import pytest
from test_cache_schema import _fem_scene, _pd_scene


def _installed() -> bool:
    try:
        return importlib.util.find_spec("omni.asset_validator") is not None
    except ModuleNotFoundError:
        return False


pytestmark = pytest.mark.skipif(
    not _installed(), reason="omniverse-asset-validator is not installed: pip install -e '.[test]'"
)
# the validator's command line (its console script omni_asset_validate), run with this interpreter
VALIDATE = [sys.executable, "-c", "import sys; from omni.asset_validator import cli_main; sys.exit(cli_main())"]

# (rule, severity) -> why it is accepted (docs/cache_format.md, "Validators")
KNOWN = {
    ("IndexedPrimvarChecker", "WARNING"): "time-varying primvars are written unindexed on purpose",
    ("NormalsValidChecker", "FAILURE"): "the rule counts the topology at the default time, which clips do not author",
}


@pytest.mark.parametrize("build", [_pd_scene, _fem_scene], ids=["peridynamics", "fem"])
def test_only_known_findings(tmp_path, build):
    """Every issue the validator reports is one of the known, explained ones (KNOWN)."""
    out = tmp_path / "cache.usdc"
    build().run(out, device="cpu", progress=False)
    report = tmp_path / "report.json"
    command = [*VALIDATE, "--json-output", str(report), str(out)]
    proc = subprocess.run(command, capture_output=True, timeout=600, check=False)
    assert report.is_file(), proc.stderr[-3000:]
    data = json.loads(report.read_text())
    found = {}
    for rule in data["rules"]:
        for issue in rule.get("issues", []):
            key = (issue["rule"]["name"], issue["severity"])
            found.setdefault(key, []).append(issue["message"])
    unknown = {k: v for k, v in found.items() if k not in KNOWN}
    assert not unknown, json.dumps({f"{k[0]} {k[1]}": v for k, v in unknown.items()}, indent=1)
