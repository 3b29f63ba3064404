"""DVC stage: train the translator (G, D; eqs. 1-6) of one (method, demos, seed) and translate the demonstrations."""

import argparse
from pathlib import Path

import torch

from lfdt import data, layout, stage, tracking, translation
from lfdt.dynamics import DynamicsModels, load_random_y
from lfdt.nets import load_state, read_config, save_state


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    stage.add_config_arguments(ap, translation.METHOD_OVERRIDES)
    args = ap.parse_args()
    p = stage.params(args.params)
    cfg = translation.method_config(args.method, p.translator)
    name = stage.config_name(args.method, args.demos, args.seed)
    dyn_cfg = read_config("models/dynamics/dynamics.pt")
    dyn = load_state(DynamicsModels(19, 6, dyn_cfg["dynamics"]["hidden"]), "models/dynamics/dynamics.pt")
    demo_paths = {pr: f"data/demos/{pr}.parquet" for pr in layout.PAIRINGS}
    episodes = {pr: data.demo_subset(path, args.demos, args.seed, pr) for pr, path in demo_paths.items()}
    demos = {pr: translation.load_x_transitions(demo_paths[pr], pr, episodes[pr]) for pr in layout.PAIRINGS}
    random_x = {pr: translation.load_x_transitions(f"data/random/{pr}.parquet", pr) for pr in layout.PAIRINGS}
    y_random = load_random_y("data/random/Y.parquet").y
    tags = {"method": args.method, "demos": args.demos, "seed": args.seed, "config": name}
    with tracking.stage_run("train_translator", {"translator": cfg.model_dump(), "method": args.method,
                                                 "demos": args.demos, "seed": args.seed},
                            tags=tags, run_name=f"train_translator-{name}") as run:
        with stage.progress(cfg.iterations, f"translator {name}", "it") as bar:
            tr, stats = translation.train_translator(demos, random_x, y_random, dyn, cfg, seed=args.seed,
                                                     std_floor=p.dynamics.std_floor,
                                                     log=lambda m, i: run.metrics(m, i), progress=bar)
        model_dir = Path("models/translator") / name
        save_state(tr, model_dir / "translator.pt", {
            "method": args.method, "demos": args.demos, "seed": args.seed, "translator": cfg.model_dump(),
            "x_columns": {pr: translation.canonical_x_columns(pr) for pr in layout.PAIRINGS},
            "y_columns": layout.state_columns("Y"), "episodes": episodes})
        df = translation.translate_demos(tr, dyn, demo_paths, episodes, cfg, p.env.timestep * p.env.frame_skip)
        table = translation.translated_table(df, {
            "kind": "translated", "domain": "Y", "method": args.method, "demos": args.demos, "seed": args.seed,
            "translator": cfg.model_dump(), "source_episodes": episodes, "layout": layout.describe(),
            "description": "demonstrations of X translated into domain Y; action.* are the BC labels "
                           f"({'F^-1(y_hat_t, y_hat_t+1)' if cfg.labels == 'inverse' else 'recorded robot + F^-1'})"})
        out = Path("data/bc_train") / name / "translated.parquet"
        data.write_table(table, out)
        with torch.no_grad():
            replay = translation.replay_check(df, p.env)
        diag = translation.translation_diagnostics(df, demo_paths, episodes)
        curve = stats.pop("curve")
        metrics = {"method": args.method, "demos": args.demos, "seed": args.seed, **replay, **diag,
                   **{f"final/{k}": v for k, v in stats.pop("final").items()}, **stats,
                   "translated_transitions": len(df), "stage_wall_s": stage.wall_since_start(),
                   "mlflow_run_id": run.run_id}
        stage.write_json(Path("reports/translator") / f"{name}.json", metrics)
        stage.write_csv(Path("reports/translator") / f"{name}_curve.csv", curve)
        run.metrics({k: v for k, v in metrics.items() if isinstance(v, int | float) and not isinstance(v, bool)})
    print(f"{name}: replay box error {replay['replay_box_position_error_m'] * 1000:.1f} mm, "
          f"replay success {replay['replay_success_rate']:.2f}, {stats['iterations_per_s']:.0f} it/s")


if __name__ == "__main__":
    stage.main(run)
