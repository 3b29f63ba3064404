"""DVC stage: the raw demonstration subsets of one demo count, every seed, for BC without translation."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import pyarrow.parquet as pq

from lfdt import data, layout, stage
from lfdt.box_push_jobs import common


def run() -> None:
    ap = stage.parser(__doc__, {"demos-dir": "the demonstrations, <pairing>.parquet",
                                "bc-data": "where the subsets go, a folder per configuration"})
    ap.add_argument("--demos", required=True, type=int)
    args = ap.parse_args()
    p = stage.params(args.params)
    for pairing in layout.PAIRINGS:  # the whole file, before any subset is written: identity, columns, values
        data.check_transitions(args.demos_dir / f"{pairing}.parquet", "demos", pairing, common.LAYOUT)
    for cfg in common.configs("bc_no_translation", args.demos, p.grid.seeds, p, bc_data_dir=args.bc_data):
        for pairing in layout.PAIRINGS:
            path = args.demos_dir / f"{pairing}.parquet"
            episodes = data.demo_subset(path, args.demos, cfg.seed, pairing)
            table = pq.read_table(path)
            keep = data.read_transitions(path, columns=["episode_index"], kind="demos",
                                         domain=pairing).episode_index.isin(episodes).to_numpy()
            data.write_table(table.filter(keep), cfg.dir(cfg.bc_data_dir) / f"raw_{pairing}.parquet")


if __name__ == "__main__":
    stage.main(run)
