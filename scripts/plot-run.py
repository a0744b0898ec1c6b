#!/usr/bin/env python3
"""One training run's curve: `success_rate_last_100` of a `crm train` metrics.jsonl against
environment steps, with wall-clock minutes on a second axis and uniform evaluations marked.

Usage: python3 scripts/plot-run.py METRICS.jsonl OUT.png [--title T] [--eval STEPS:RATE:LABEL ...]
(needs matplotlib: pip install matplotlib). `--eval 4096000:0.830:seed 0` marks a `crm eval`
of the checkpoint at that step; the log's own rate is over the curriculum's draw when the run
used `--curriculum`, so it reads lower than a uniform evaluation.
"""
import argparse
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("metrics")
    parser.add_argument("out")
    parser.add_argument("--title", default="")
    parser.add_argument("--eval", action="append", default=[], metavar="STEPS:RATE:LABEL")
    args = parser.parse_args()
    rows = []
    with open(args.metrics) as f:
        for number, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
                rows.append((row["steps"], row["wall_s"], row["success_rate_last_100"]))
            except (ValueError, KeyError) as e:
                sys.exit(f"{args.metrics}, line {number}: not a crm train metric row ({e})")
    if not rows:
        sys.exit(f"{args.metrics}: no metric rows")
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot([r[0] / 1e6 for r in rows], [r[2] for r in rows], lw=0.8,
            label="success, last 100 training episodes")
    for spec in args.eval:
        try:
            steps, rate, label = spec.split(":", 2)
            ax.plot(int(steps) / 1e6, float(rate), "o", label=f"crm eval, {label}: {float(rate):.3f}")
        except ValueError:
            sys.exit(f"--eval {spec!r}: expected STEPS:RATE:LABEL")
    ax.set_xlabel("environment steps (millions)")
    ax.set_ylabel("success")
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3)
    top = ax.secondary_xaxis(
        "top",
        functions=(lambda m: m * 1e6 * rows[-1][1] / 60 / rows[-1][0],
                   lambda t: t * 60 * rows[-1][0] / rows[-1][1] / 1e6),
    )
    top.set_xlabel("wall-clock minutes (at the run's mean rate)")
    ax.legend(loc="lower right", fontsize=8)
    if args.title:
        ax.set_title(args.title, fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)


if __name__ == "__main__":
    main()
