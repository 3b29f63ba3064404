"""The numeric fingerprint on other CPUs: this machine's, and CPU models emulated by QEMU's user mode.

Runs ``python -m lfdt.box_push_jobs.fingerprint`` natively (pinned, and with ``LFDT_NUMERICS=native`` as a negative
control, which should differ where this CPU has AVX-512) and under ``qemu-x86_64 -cpu <model>`` for each model asked for
(QEMU 7.2's TCG emulates AVX2 and FMA but not AVX-512: each emulated model is a CPU of another vendor or generation
without AVX-512, whose CPUID the libraries read to pick their kernels). Compares every result with the committed
``reports/fingerprint.json`` and writes ``reports/cross_cpu.json``: the host's CPU model, the date, each run's hashes
and whether they match. QEMU comes from Debian's ``qemu-user`` package (``apt-get install qemu-user``); each emulated
run takes one to three minutes.

    python tools/cross_cpu.py --models Haswell EPYC Skylake-Client EPYC-Rome
"""

import lfdt.numerics  # noqa: F401

import argparse
import datetime
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from lfdt import numerics

ROOT = Path(__file__).resolve().parents[1]


def run_fingerprint(prefix: list[str], env: dict[str, str], timeout: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "fp.json"
        r = subprocess.run([*prefix, sys.executable, "-m", "lfdt.box_push_jobs.fingerprint", "--out", str(out)],
                           cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout)
        if r.returncode != 0:
            tail = "\n".join(line for line in r.stderr.splitlines() if "TCG doesn't support" not in line)[-2000:]
            raise RuntimeError(f"{' '.join(prefix) or 'native'}: fingerprint failed:\n{tail}")
        return json.loads(out.read_text())


def earlier_hosts(path: Path, host: str) -> list[dict]:
    """The last report's runs on other host CPUs (each host's latest), kept so that a run on this machine does not
    erase what another CPU reproduced: each with its date and the fingerprint it was compared with."""
    if not path.exists():
        return []
    old = json.loads(path.read_text())
    keep = {e["host_cpu_model"]: e for e in old.get("earlier_hosts", [])}
    keep[old["host_cpu_model"]] = {k: old[k] for k in ("date", "host_cpu_model", "host_cpu_isa", "qemu", "committed",
                                                       "runs")}
    return [e for h, e in sorted(keep.items()) if h != host]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", nargs="*", default=["Haswell", "EPYC"], help="QEMU CPU models (qemu-x86_64 -cpu help)")
    ap.add_argument("--out", type=Path, default=ROOT / "reports" / "cross_cpu.json")
    ap.add_argument("--timeout", type=int, default=1800, help="seconds per run")
    args = ap.parse_args()
    committed = json.loads((ROOT / "reports" / "fingerprint.json").read_text())
    qemu = shutil.which("qemu-x86_64")
    if args.models and qemu is None:
        sys.exit("tools/cross_cpu.py: qemu-x86_64 not found (Debian: apt-get install qemu-user)")
    base = {k: v for k, v in os.environ.items() if k not in numerics.PINNED_ENV and k != numerics.SWITCH}
    runs = []
    plan = [("native", [], {}), ("native, LFDT_NUMERICS=native (negative control)", [], {numerics.SWITCH: "native"})]
    plan += [(f"QEMU {m}", [qemu, "-cpu", m], {}) for m in args.models]
    for label, prefix, extra in plan:
        print(f"{label} ...", file=sys.stderr, flush=True)
        doc = run_fingerprint(prefix, {**base, **extra}, args.timeout)
        same = {k: doc["components"].get(k) == v for k, v in committed["components"].items()}
        runs.append({"cpu": label if prefix else f"{numerics.cpu_model()} ({numerics.isa()}), {label}",
                     "emulated_model": prefix[2] if prefix else None, "numerics": doc["numerics"],
                     "components": doc["components"], "matches_committed": same, "all_match": all(same.values())})
        print(f"  {'matches' if all(same.values()) else 'DIFFERS from'} the committed fingerprint "
              f"({sum(same.values())}/{len(same)} components)", file=sys.stderr)
    qemu_version = subprocess.run([qemu, "--version"], capture_output=True, text=True).stdout.split("\n")[0] \
        if qemu else None
    report = {"date": datetime.date.today().isoformat(), "host_cpu_model": numerics.cpu_model(),
              "host_cpu_isa": numerics.isa(), "qemu": qemu_version, "committed": committed["components"],
              "runs": runs, "earlier_hosts": earlier_hosts(args.out, numerics.cpu_model())}
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
