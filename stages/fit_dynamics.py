"""DVC stage: fit the forward model F and the inverse model F^-1 on domain Y's random-motion data."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import os

from lfdt import dynamics, stage
from lfdt.box_push_jobs.common import DYNAMICS_FILE
from lfdt.nets import save_state, torch_device
from lfdt.tasks.box_push import columns as box_columns
from lfdt.tasks.box_push.random_motion import push_probe


def run() -> None:
    ap = stage.parser(__doc__, {"random-dir": "the random motion, Y.parquet", "out-dir": "where dynamics.pt goes",
                                "report": "the report (a JSON file under reports/)",
                                "curve": "the learning curve (CSV)"})
    args = ap.parse_args()
    p = stage.params(args.params)
    cfg, device = p.dynamics, torch_device(p.device)
    d = dynamics.load_random_y(str(args.random_dir / "Y.parquet"), box_columns.BOX_PUSH)
    with stage.frame(args.report, "fit_dynamics", {"dynamics": cfg.model_dump(), "device": p.device},
                     tags={"domain": "Y", "seed": cfg.seed}, run_name="fit_dynamics") as f:
        # F and F^-1 side by side in two processes when there are two cores: the same bits as one after the other
        models, res = dynamics.fit_dynamics(d, cfg, log=lambda m, i: f.metrics(m, i), device=device,
                                            workers=min(2, os.cpu_count() or 1))
        curve = res.pop("curve")
        save_state(models, args.out_dir / DYNAMICS_FILE, {
            "dynamics": cfg.model_dump(), "state_columns": box_columns.state_columns("Y"),
            "action_columns": box_columns.action_columns("Y"), "y_norm": models.y_norm.to_dict(),
            "delta_scale": models.delta_scale.tolist(),
            "forward": "y_n + delta_scale * f([y_n, a])", "inverse": "g([y_n, (y2_n - y_n) / delta_scale])"})
        groups = {"arms": [c for c in box_columns.state_columns("Y") if not c.startswith("box.")],
                  "box": list(box_columns.OBJECT_COLUMNS)}
        for name, cols in groups.items():
            f_mse = sum(res["forward_mse_per_column"][c] for c in cols)
            t_mse = sum(res["forward_trivial_mse_per_column"][c] for c in cols)
            res[f"forward_ratio_{name}"] = f_mse / t_mse
        # F where the demonstrations are: two arms pushing the box, in and out of step (not in its training data)
        probe = dynamics.object_frame_ratios(models.cpu(), *push_probe(p.env), box_columns.BOX_PUSH)
        res.update({f"pushes/forward_ratio_{k}": v for k, v in probe.items()})
        metrics = {k: v for k, v in res.items() if not isinstance(v, dict)}
        f.report.update({**metrics, "per_column": {
            "forward_mse": res["forward_mse_per_column"], "forward_trivial_mse": res["forward_trivial_mse_per_column"],
            "inverse_mse": res["inverse_mse_per_column"]}})
        stage.write_csv(args.curve, curve)
        f.metrics(metrics)
    print(f"F: held-out MSE {res['forward_mse']:.4g} = {res['forward_ratio']:.3f} x trivial (bar 0.2); "
          f"F^-1: {res['inverse_mse']:.4g} = {res['inverse_ratio']:.3f} x mean action (bar 0.5); "
          f"F on two-arm pushes, box across / along / yaw: {probe['across']:.2f} / {probe['along']:.2f} / "
          f"{probe['angle']:.2f} x no change")


if __name__ == "__main__":
    stage.main(run)
