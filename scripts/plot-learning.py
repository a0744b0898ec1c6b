"""Draws docs/learning/*.png from the metric logs in docs/learning/ (crm train's metrics.jsonl).

Usage: python3 scripts/plot-learning.py   (needs matplotlib: pip install matplotlib)
"""

import json
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs" / "learning"


def load(name):
    return [json.loads(line) for line in (DOCS / name).read_text().splitlines() if line.strip()]


def curve(ax, rows, x, label):
    xs = [r[x] / (60.0 if x == "wall_s" else 1e6) for r in rows]
    ax.plot(xs, [r["success_rate_last_100"] for r in rows], label=label)


def main():
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    ax = axes[0]
    for name, label in [
        ("benchmark-k.metrics.jsonl", "run k, the shipped model: 3.75 M steps, seed 1"),
        ("benchmark-l.metrics.jsonl", "run l: run k's command, seed 0"),
        ("benchmark-m.metrics.jsonl", "run m: run k's command, seed 2"),
        ("benchmark-n.metrics.jsonl", "run n: run k's command, seed 3"),
        ("benchmark-j.metrics.jsonl", "run j: 4.6 M steps, seed 1"),
        ("benchmark-i.metrics.jsonl", "run i: task curriculum (hard tasks drawn more), seed 0"),
        ("benchmark-h.metrics.jsonl", "run h: uniform tasks, lock-step rollouts"),
        ("benchmark-g.metrics.jsonl", "run g (earlier rules)"),
    ]:
        if (DOCS / name).exists():
            curve(ax, load(name), "wall_s", label)
    ax.set_xlabel("wall-clock minutes, 2 cores")
    ax.set_ylabel("success rate, last 100 training episodes")
    ax.set_title("CRM-PPO from scratch, all 26 tasks")
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=7)

    ax = axes[1]
    for name, label in [
        ("box-lift-closing.metrics.jsonl", "closing-only fingers"),
        ("box-lift-signed.metrics.jsonl", "signed finger increments"),
    ]:
        curve(ax, load(name), "steps", label)
    ax.set_xlabel("environment steps (millions)")
    ax.set_title("box-lift, seed 0: finger actions")
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(DOCS / "curves.png", dpi=110)


if __name__ == "__main__":
    main()
