"""DVC stage: the raw demonstration subsets of one demo count, every seed, for BC without translation."""

import argparse

import pyarrow.parquet as pq

from lfdt import data, layout, stage
from lfdt.jobs import common


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--demos", required=True, type=int)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = stage.params(args.params)
    for cfg in common.configs("bc_no_translation", args.demos, p.grid.seeds, args.params):
        for pairing in layout.PAIRINGS:
            path = common.DEMOS / f"{pairing}.parquet"
            episodes = data.demo_subset(path, args.demos, cfg.seed, pairing)
            table = pq.read_table(path)
            keep = data.read_transitions(path, columns=["episode_index"], kind="demos",
                                         domain=pairing).episode_index.isin(episodes).to_numpy()
            data.write_table(table.filter(keep), cfg.dir(common.BC_DATA) / f"raw_{pairing}.parquet")


if __name__ == "__main__":
    stage.main(run)
