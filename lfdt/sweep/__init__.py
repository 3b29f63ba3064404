"""Past one machine: the pipeline's matrix fanned out over a Ray cluster, results shared through a DVC remote's run
cache, runs tracked on one MLflow server. Entry point: ``python -m lfdt.sweep`` (README, 'When one machine is not
enough')."""
