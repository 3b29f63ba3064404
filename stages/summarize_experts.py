"""DVC stage: reports/experts.json, one entry per pairing (expert evaluation + demonstration statistics)."""

import argparse
import json
from pathlib import Path

from lfdt import layout, stage


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.parse_args()
    out = {}
    for pairing in layout.PAIRINGS:
        train = json.loads(Path(f"reports/experts/{pairing}_train.json").read_text())
        demos = json.loads(Path(f"reports/demos/{pairing}.json").read_text())
        out[pairing] = {
            "success_rate": train["success_rate"],
            "episodes": train["episodes"],
            "mean_demo_length": demos["mean_demo_length"],
            "demo_attempts": demos["attempts"],
            "demo_success_rate": demos["success_rate"],
            "train_timesteps": train["timesteps"],
            "train_wall_time_s": train["wall_time_s"],
            "env_steps_per_s": train["env_steps_per_s"],
            "gradient_steps_per_s": train["gradient_steps_per_s"],
        }
    stage.write_json("reports/experts.json", out)


if __name__ == "__main__":
    stage.main(run)
