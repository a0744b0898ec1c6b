#!/usr/bin/env python3
"""A run as MLflow's own client reads it back from a tracking server, for the tests
(tests/mlflow.rs): `mlflow-run.py URI EXPERIMENT DOWNLOAD_DIR` prints one JSON object for the
experiment's only run: {"run_id", "status", "params", "tags", "metrics": {KEY: [[STEP,
VALUE], ...]}, "artifacts": [PATH, ...]}, and downloads its artifacts into DOWNLOAD_DIR.
"""

import json
import sys

from mlflow.tracking import MlflowClient


def main(uri, experiment, download):
    client = MlflowClient(tracking_uri=uri)
    found = client.get_experiment_by_name(experiment)
    runs = client.search_runs([found.experiment_id])
    if len(runs) != 1:
        raise SystemExit(f"{len(runs)} runs in experiment {experiment}, not 1")
    run = runs[0]
    metrics = {
        key: [[m.step, m.value] for m in client.get_metric_history(run.info.run_id, key)]
        for key in run.data.metrics
    }
    artifacts = [a.path for a in client.list_artifacts(run.info.run_id)]
    client.download_artifacts(run.info.run_id, "", download)
    print(
        json.dumps(
            {
                "run_id": run.info.run_id,
                "status": run.info.status,
                "params": run.data.params,
                "tags": run.data.tags,
                "metrics": metrics,
                "artifacts": artifacts,
            }
        )
    )


if __name__ == "__main__":
    main(*sys.argv[1:4])
