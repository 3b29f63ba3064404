"""DVC stage: reports/experts.json, one entry per pairing (expert evaluation + demonstration statistics), and the
protocol's premise measured: both robots replaying their programs together in Y, nobody adapting."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

from lfdt import layout, stage
from lfdt.tasks.box_push import programmed

PREMISE_EPISODES = 200
PREMISE_GATE = 0.30
"""The most the two pairings' robot halves together may succeed by the path rule for the protocol's premise to hold
(issue 37): the paper's BC without translation succeeds 7-28 %."""


def run() -> None:
    ap = stage.parser(__doc__, {"expert-reports": "the experts' reports, <pairing>_train.json",
                                "demo-reports": "the demonstrations' reports, <pairing>.json",
                                "out": "the summary (a JSON file under reports/)"})
    args = ap.parse_args()
    p = stage.params(args.params)
    out: dict = {"protocol": p.demos.protocol}
    for pairing in layout.PAIRINGS:
        train = stage.read_report(args.expert_reports / f"{pairing}_train.json")
        demos = stage.read_report(args.demo_reports / f"{pairing}.json")
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
    # start states of the development block: never those of the evaluation
    together = programmed.programs_together_success(p.env, p.demos.program, PREMISE_EPISODES)
    out["programs_together_in_Y"] = {
        "success_rate": together["end"], "path_success_rate": together["path"], "episodes": PREMISE_EPISODES,
        "gate": PREMISE_GATE, "gate_met": together["path"] <= PREMISE_GATE,
        "description": "both robots replay takes of their own programs together in Y, nobody adapting: the two "
                       "pairings' robot halves together; the premise gate is on the path rule"}
    stage.write_report(args.out, out)
    print(f"two programmed robots together in Y over {PREMISE_EPISODES} development start states: "
          f"{together['end']:.2f} success, {together['path']:.2f} by the path rule (premise gate <= {PREMISE_GATE})")

if __name__ == "__main__":
    stage.main(run)
