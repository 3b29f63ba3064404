"""The numeric fingerprint: this machine's hashes equal the committed ones (where the numeric code paths are
pinned, every x86-64 CPU with AVX2 should give them), and the pin refuses to come too late."""

import lfdt.numerics  # noqa: F401

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from lfdt import numerics
from lfdt.box_push_jobs import fingerprint

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_this_cpu_computes_the_committed_fingerprint():
    committed = json.loads((ROOT / "reports" / "fingerprint.json").read_text())
    if not numerics.pinned():
        pytest.skip(f"{numerics.SWITCH}=native: the fingerprint is only comparable across CPUs when pinned")
    assert committed["numerics"] == "pinned"
    here = fingerprint.report(fingerprint.compute())
    if here["versions"] != committed["versions"]:
        pytest.skip(f"other library versions than the committed fingerprint's: {here['versions']}")
    moved = {k: (committed["components"].get(k), v) for k, v in here["components"].items()
             if committed["components"].get(k) != v}
    info = numerics.describe()
    assert not moved, (f"on {info['cpu_model']} ({info['cpu_isa']}) these components give other bits than the "
                       f"committed reports/fingerprint.json: {moved}")


def _python(code: str, **env) -> subprocess.CompletedProcess:
    full = {k: v for k, v in os.environ.items() if k not in numerics.PINNED_ENV and k != numerics.SWITCH}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={**full, **env},
                          cwd=ROOT, timeout=120)


def test_the_pin_fails_loudly_when_numpy_loaded_first():
    r = _python("import numpy, lfdt")
    assert r.returncode != 0 and "numpy loaded before lfdt.numerics" in r.stderr


def test_the_pin_sets_the_kernels_before_torch_loads():
    r = _python("import lfdt, torch; print(torch.backends.cpu.get_cpu_capability())")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() in ("AVX2", "DEFAULT")  # DEFAULT only on a CPU without AVX2, which the pin refuses


def test_the_switch_turns_the_pin_off_and_a_wrong_value_is_named():
    r = _python("import os, lfdt; print(os.environ.get('MKL_CBWR', 'unset'))", LFDT_NUMERICS="native")
    assert r.returncode == 0 and r.stdout.strip() == "unset"
    r = _python("import lfdt", LFDT_NUMERICS="fast")
    assert r.returncode != 0 and "LFDT_NUMERICS='fast': expected one of pinned, native" in r.stderr
