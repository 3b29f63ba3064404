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


def _load_cross_cpu():
    import importlib.util

    spec = importlib.util.spec_from_file_location("cross_cpu", ROOT / "tools" / "cross_cpu.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_a_cross_cpu_run_keeps_what_other_host_cpus_reproduced(tmp_path):
    """tools/cross_cpu.py run on one machine keeps the last report's rows of other host CPUs (dated), drops this
    host's old ones, and the README's generated table shows both."""
    from lfdt import docs

    def report(host: str, date: str, components: dict, earlier=()) -> dict:
        run = {"cpu": f"{host} (avx2), native", "emulated_model": None, "numerics": "pinned", "components": components,
               "matches_committed": dict.fromkeys(components, True), "all_match": True}
        return {"date": date, "host_cpu_model": host, "host_cpu_isa": "avx2", "qemu": "qemu 7.2",
                "committed": components, "runs": [run], "earlier_hosts": list(earlier)}

    old = tmp_path / "cross_cpu.json"
    old.write_text(json.dumps(report("CPU A", "2026-01-01", {"x": "1"},
                                     [report("CPU B", "2025-12-31", {"x": "1"}) | {"earlier_hosts": []}])))
    kept = _load_cross_cpu().earlier_hosts(old, "CPU B")  # now on CPU B: A's rows stay, B's old ones go
    assert [e["host_cpu_model"] for e in kept] == ["CPU A"] and kept[0]["date"] == "2026-01-01"
    root = tmp_path / "root"
    (root / "reports").mkdir(parents=True)
    (root / "reports" / "cross_cpu.json").write_text(json.dumps(report("CPU B", "2026-02-01", {"x": "1", "y": "2"},
                                                                       kept)))
    (root / "reports" / "fingerprint.json").write_text(json.dumps({"components": {"x": "1", "y": "2"},
                                                                   "versions": {"torch": "t"}}))
    text = docs.cross_cpu(root)
    assert "| CPU B | AVX2 | pinned | yes, all 2 components compared |" in text
    assert "| CPU A, 2026-01-01 | AVX2 | pinned | yes, all 1 components compared |" in text
    assert "The rows dated 2026-01-01 ran on CPU A" in text
