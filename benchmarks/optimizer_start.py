"""What a training process's first optimizer costs: lfdt.optim's Adam as it starts now (torch's compiler never
imported) against the same process importing ``torch._dynamo`` first, as each process did when torch's optimizer
wrapping imported it on the optimizer's construction.

Each process imports the stage code a BC worker imports, builds a small policy and its Adam, and takes one step;
the two kinds alternate, ``--repeats`` times each; times are each process's wall and CPU seconds (start to exit).
The ratio is the median CPU time with the compiler over the median without it (> 1: the saving).

Writes benchmarks/results/optimizer_start.json.
"""

import argparse
import json
import platform
import resource
import statistics
import subprocess
import sys
import time
from datetime import date
from pathlib import Path

CHILD = """
import lfdt.numerics
{first}
import torch
import lfdt.box_push_jobs.bc
from lfdt.optim import Adam
net = torch.nn.Sequential(torch.nn.Linear(40, 256), torch.nn.ReLU(), torch.nn.Linear(256, 8))
opt = Adam(net.parameters(), lr=1e-3)
opt.zero_grad()
net(torch.ones(4, 40)).sum().backward()
opt.step()
"""
KINDS = {"without_compiler": "", "with_compiler": "import torch._dynamo"}


def one(kind: str) -> tuple[float, float]:
    """Wall and CPU seconds of one fresh process of ``kind``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", CHILD.format(first=KINDS[kind])], check=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    """Run the benchmark and write its JSON."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--out", default=str(Path(__file__).parent / "results" / "optimizer_start.json"))
    args = p.parse_args()
    from lfdt import numerics

    times = {k: {"wall_s": [], "cpu_s": []} for k in KINDS}
    one("without_compiler")  # warm the file cache
    for _ in range(args.repeats):
        for kind in KINDS:
            wall, cpu = one(kind)
            times[kind]["wall_s"].append(wall)
            times[kind]["cpu_s"].append(cpu)
    med = {k: {m: statistics.median(v) for m, v in t.items()} for k, t in times.items()}
    result = {"benchmark": __doc__.splitlines()[0], "repeats": args.repeats, "times": times, "median": med,
              "ratio_cpu_with_over_without": med["with_compiler"]["cpu_s"] / med["without_compiler"]["cpu_s"],
              "saved_cpu_s": med["with_compiler"]["cpu_s"] - med["without_compiler"]["cpu_s"],
              "cpu_model": numerics.describe()["cpu_model"], "python": platform.python_version(),
              "date": date.today().isoformat()}
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(f"one process, CPU s: {med['without_compiler']['cpu_s']:.2f} without the compiler, "
          f"{med['with_compiler']['cpu_s']:.2f} with it (ratio {result['ratio_cpu_with_over_without']:.2f})")


if __name__ == "__main__":
    main()
