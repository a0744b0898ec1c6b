#!/usr/bin/env python3
"""The figures `crm results` reports, computed by the `rliable` package itself (Agarwal et al.
2021), for the agreement test (worker/tests/results.rs): `rliable-figures.py SCORES.json`
reads the same input as `crm results --stats-of` ({"scores": {ALGO: [[task scores of a run],
...]}, "reference": ALGO, "reps": N, "seed": S}) and prints one JSON line in its output's
shape: per algorithm the IQM, mean, median and optimality gap with their 95% stratified-
bootstrap intervals, and P(reference > other) with its interval.
"""

import json
import sys
import warnings

import numpy as np
from rliable import library as rly
from rliable import metrics


def main(path):
    # arch warns that `random_state` will go; rliable 1.2.0 passes it.
    warnings.simplefilter("ignore", FutureWarning)
    with open(path) as f:
        request = json.load(f)
    scores = {a: np.array(rows, dtype=float) for a, rows in request["scores"].items()}
    reps = request.get("reps", 50000)
    state = np.random.RandomState(request.get("seed", 0))
    names = ["iqm", "mean", "median", "optimality_gap"]

    def aggregate(x):
        return np.array(
            [
                metrics.aggregate_iqm(x),
                metrics.aggregate_mean(x),
                metrics.aggregate_median(x),
                metrics.aggregate_optimality_gap(x),
            ]
        )

    points, intervals = rly.get_interval_estimates(
        scores, aggregate, reps=reps, random_state=state
    )
    out = {"aggregates": {}, "improvement": {}}
    for algorithm in scores:
        out["aggregates"][algorithm] = {
            name: {
                "point": float(points[algorithm][k]),
                "low": float(intervals[algorithm][0][k]),
                "high": float(intervals[algorithm][1][k]),
            }
            for k, name in enumerate(names)
        }
    reference = request.get("reference")
    if reference is not None:
        pairs = {
            other: (scores[reference], scores[other])
            for other in scores
            if other != reference
        }
        points, intervals = rly.get_interval_estimates(
            pairs, metrics.probability_of_improvement, reps=reps, random_state=state
        )
        for other in pairs:
            out["improvement"][other] = {
                "point": float(np.ravel(points[other])[0]),
                "low": float(np.ravel(intervals[other][0])[0]),
                "high": float(np.ravel(intervals[other][1])[0]),
            }
    print(json.dumps(out))


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: rliable-figures.py SCORES.json")
    main(sys.argv[1])
