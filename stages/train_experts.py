"""DVC stage: train the SAC experts of both pairings side by side (each resumable), evaluate them on fresh seeds."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

from lfdt import layout, parallel, stage
from lfdt.box_push_jobs.experts import ExpertJob, expert_job
from lfdt.nets import torch_device


def run() -> None:
    ap = stage.parser(__doc__, {"experts": "where the experts go, a folder per pairing",
                                "checkpoints": "resumable training checkpoints, a folder per pairing",
                                "reports": "where the reports <pairing>_train.json and learning curves go"})
    args = ap.parse_args()
    p = stage.params(args.params)
    torch_device(p.device)  # before any job starts
    jobs = [ExpertJob(pr, p, args.experts, args.checkpoints, args.reports) for pr in layout.PAIRINGS]
    results = parallel.run_jobs(expert_job, jobs, p.grid.workers,
                                total=p.experts.total_timesteps * len(layout.PAIRINGS), desc="SAC experts",
                                unit="step")
    for r in results:
        print(f"{r['pairing']}: success rate {r['success_rate']:.2f} over {r['episodes']} episodes, "
              f"{r['wall_time_s'] / 60:.1f} min, {r['env_steps_per_s']:.0f} env steps/s")


if __name__ == "__main__":
    stage.main(run)
