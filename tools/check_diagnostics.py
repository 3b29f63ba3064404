"""Recompute one translator's diagnostics on this CPU and compare them, bit for bit, with the committed report.

The translator stage reports, beside each seed's weights, what the translator does (``reports/translator/<method>-
d<demos>.json``: L_dyn split, D's accuracies, F^-1's labels, the kinematics' residuals, the offsets across the box,
the open-loop replay of the translated demonstrations in MuJoCo). This tool loads that seed's saved translators
(``dvc pull`` or ``dvc repro`` first), recomputes every one of those values with the project's own code and the
project's params.yaml, and prints which differ from the report (exit 1) or that all match (exit 0). Run on another
CPU than the one that wrote the report, it says whether the diagnostics reproduce there (the fingerprint's
``diagnostics`` component checks the same code on a tiny workload)::

    python tools/check_diagnostics.py --method lfdt --demos 50 --seed 100
"""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths)

import argparse
import json
import sys
from pathlib import Path

import torch
import yaml

from lfdt import layout, methods, numerics
from lfdt.box_push_jobs.common import DYNAMICS_FILE, LAYOUT
from lfdt.box_push_jobs.translator import box_push_kinematics, measure_translation, seed_demos
from lfdt.config import load_params
from lfdt.dynamics import load_models, load_random_y
from lfdt.errors import InputError, StageError
from lfdt.nets import load_state
from lfdt.translation.training import new_translator
from lfdt.translation.transitions import load_x_transitions


def dvc_paths(root: Path) -> dict[str, dict[str, str]]:
    """The ``paths`` and ``reports`` of dvc.yaml's vars (where every path is written once)."""
    out: dict[str, dict[str, str]] = {}
    for block in yaml.safe_load((root / "dvc.yaml").read_text())["vars"]:
        out.update(block)
    return out


def recompute(root: Path, method: str, demos: int, seed: int) -> dict[str, float]:
    """The diagnostics of ``method``'s translator for ``demos`` demonstrations and training seed ``seed``, as the
    translator stage computes them (:func:`~lfdt.box_push_jobs.translator.measure_translation`)."""
    torch.set_num_threads(1)
    p = load_params(root / "params.yaml")
    paths = {k: root / v for k, v in dvc_paths(root)["paths"].items()}
    tcfg = methods.translator_config(method, p.translator)
    kin = box_push_kinematics(p.env)
    dyn = load_models(paths["dynamics"] / DYNAMICS_FILE)
    demo_paths = {pr: paths["demos"] / f"{pr}.parquet" for pr in layout.PAIRINGS}
    random_x = {pr: load_x_transitions(paths["random"] / f"{pr}.parquet", pr, tl=LAYOUT, kind="random")
                for pr in layout.PAIRINGS}
    y_random = load_random_y(paths["random"] / "Y.parquet", LAYOUT).y
    episodes, demos_all = seed_demos(demo_paths, demos, seed)
    folder = paths["translators"] / f"{method}-d{demos}" / f"s{seed}"
    files = sorted(folder.glob("translator*.pt"))
    if not files:
        raise InputError(f"{folder} holds no translator*.pt (dvc pull, or dvc repro the translator stage)")
    trs = [load_state(new_translator(tcfg, LAYOUT, kin), f) for f in files]
    return measure_translation(trs, dyn, tcfg, demo_paths, episodes, demos_all, random_x, y_random, kin, p.env,
                               seed)[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--method", default="lfdt", help="a translator method (grid.translator_methods)")
    ap.add_argument("--demos", type=int, required=True, help="demonstrations per pairing (grid.demos)")
    ap.add_argument("--seed", type=int, required=True, help="training seed (grid.seeds)")
    ap.add_argument("--root", type=Path, default=Path("."), help="the project (params.yaml, models, data, reports)")
    args = ap.parse_args()
    try:
        report = args.root / "reports" / dvc_paths(args.root)["reports"]["translator"] / \
            f"{args.method}-d{args.demos}.json"
        seeds = json.loads(report.read_text())["seeds"]
        if str(args.seed) not in seeds:
            raise InputError(f"{report} has no seed {args.seed} (it has {', '.join(sorted(seeds))})")
        committed = seeds[str(args.seed)]
        here = recompute(args.root, args.method, args.demos, args.seed)
    except (OSError, KeyError, ValueError, StageError) as err:
        sys.exit(f"error: {args.method}-d{args.demos} seed {args.seed} under {args.root.resolve()}: "
                 f"{type(err).__name__}: {err}")
    info = numerics.describe()
    differ = {k: (committed.get(k), v) for k, v in here.items() if committed.get(k) != v}
    where = f"{info['cpu_model']} ({info['cpu_isa']}, numerics {info['numerics']})"
    if differ:
        for k, (old, new) in sorted(differ.items()):
            print(f"DIFFERS {k}: report {old!r}, here {new!r}")
        sys.exit(f"{len(differ)} of {len(here)} diagnostics differ from {report} on {where}")
    print(f"all {len(here)} diagnostics of {args.method}-d{args.demos} seed {args.seed} match {report} bit for bit "
          f"on {where}")


if __name__ == "__main__":
    main()
