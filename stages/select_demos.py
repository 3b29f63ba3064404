"""DVC stage: the raw demonstration subset of one (demos, seed) for BC without translation."""

import argparse
from pathlib import Path

import pyarrow.parquet as pq

from lfdt import data, layout, stage


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--demos", required=True, type=int)
    ap.add_argument("--seed", required=True, type=int)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    stage.params(args.params)
    out_dir = Path("data/bc_train") / stage.config_name("bc_no_translation", args.demos, args.seed)
    for pairing in layout.PAIRINGS:
        path = f"data/demos/{pairing}.parquet"
        episodes = data.demo_subset(path, args.demos, args.seed, pairing)
        table = pq.read_table(path)
        keep = data.read_transitions(path, columns=["episode_index"]).episode_index.isin(episodes).to_numpy()
        data.write_table(table.filter(keep), out_dir / f"raw_{pairing}.parquet")


if __name__ == "__main__":
    stage.main(run)
