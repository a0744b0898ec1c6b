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


def curve(ax, rows, x, label, **style):
    xs = [r[x] / (60.0 if x == "wall_s" else 1e6) for r in rows]
    ax.plot(xs, [r["success_rate_last_100"] for r in rows], label=label, **style)


def phases(*names):
    """Metric logs of one run trained in phases (`crm train --resume`): each phase's wall
    clock continues where the one before ended."""
    rows, offset, ends = [], 0.0, []
    for name in names:
        part = load(name)
        rows += [dict(r, wall_s=r["wall_s"] + offset) for r in part]
        offset = rows[-1]["wall_s"]
        ends.append(offset / 60.0)
    return rows, ends[:-1]


def task_map(rows, marks, title, path):
    """Each task's training success (`task_success`, its last 50 episodes) over wall-clock
    minutes, weakest at the end on top."""
    rows = [r for r in rows if r.get("task_success")]
    tasks = sorted(rows[-1]["task_success"], key=lambda t: rows[-1]["task_success"][t])
    grid = [[r["task_success"].get(t, float("nan")) for r in rows] for t in tasks]
    # Each iteration's column spans the wall-clock time since the one before it.
    edges = [0.0] + [r["wall_s"] / 60.0 for r in rows]
    fig, ax = plt.subplots(figsize=(11, 6))
    image = ax.pcolormesh(
        edges,
        [k - 0.5 for k in range(len(tasks) + 1)],
        grid,
        cmap="viridis",
        vmin=0,
        vmax=1,
    )
    ax.invert_yaxis()
    for minute in marks:
        ax.axvline(minute, color="white", linestyle="--", linewidth=1)
    ax.set_yticks(range(len(tasks)))
    ax.set_yticklabels(tasks, fontsize=7)
    ax.set_xlabel("wall-clock minutes, 2 cores")
    ax.set_title(title)
    fig.colorbar(image, ax=ax, label="training success, last 50 episodes of the task")
    fig.tight_layout()
    fig.savefig(DOCS / path, dpi=110)


def main():
    fig, axes = plt.subplots(1, 2, figsize=(14, 4.5), gridspec_kw={"width_ratios": [1.5, 1]})
    ax = axes[0]
    two_phase = ("benchmark-p.metrics.jsonl", "benchmark-q.metrics.jsonl")
    if all((DOCS / name).exists() for name in two_phase):
        rows, marks = phases(*two_phase)
        curve(ax, rows, "wall_s", "run q (v2): 1 s hold, then 5 s, seed 1", color="black", alpha=0.4, linewidth=0.8)
        task_map(
            rows,
            marks,
            "run q per task: a 1 s hold until the dashed line (run p), then the paper's 5 s",
            "tasks-q.png",
        )
    for name, label, style in [
        ("benchmark-t.metrics.jsonl", "run t (v4), shipped: early stop 99% of 1,000, seed 1 (logged: last 1,000)", {"color": "crimson", "linewidth": 2}),
        ("benchmark-u.metrics.jsonl", "run u (v4): run t's command, seed 0 (logged: last 1,000)", {"color": "navy", "linewidth": 2}),
        ("benchmark-v.metrics.jsonl", "run v (v4): run t's command, seed 2 (logged: last 1,000)", {"color": "teal", "linewidth": 2}),
        ("benchmark-r.metrics.jsonl", "run r (v4): early stop 99% of 100, seed 1", {"color": "gold", "linewidth": 2}),
    ]:
        if (DOCS / name).exists():
            curve(ax, load(name), "wall_s", label, **style)
    if (DOCS / "benchmark-t.metrics.jsonl").exists():
        task_map(
            load("benchmark-t.metrics.jsonl"),
            [],
            "run t per task, the shipped model (environment v4, friction anchors)",
            "tasks-t.png",
        )
    for name, label in [
        ("benchmark-k.metrics.jsonl", "run k (v2, shipped before): seed 1"),
        ("benchmark-l.metrics.jsonl", "run l: run k's command, seed 0"),
        ("benchmark-m.metrics.jsonl", "run m: run k's command, seed 2"),
        ("benchmark-n.metrics.jsonl", "run n: run k's command, seed 3"),
        ("benchmark-j.metrics.jsonl", "run j: 4.6 M steps, seed 1"),
        ("benchmark-i.metrics.jsonl", "run i: task curriculum, seed 0"),
        ("benchmark-h.metrics.jsonl", "run h: uniform tasks, lock-step rollouts"),
        ("benchmark-g.metrics.jsonl", "run g (earlier rules)"),
    ]:
        if (DOCS / name).exists():
            curve(ax, load(name), "wall_s", label, alpha=0.4, linewidth=0.8)
    ax.set_xlabel("wall-clock minutes, 2 cores")
    ax.set_ylabel("success rate, last 100 training episodes")
    ax.set_title("CRM-PPO from scratch, all 26 tasks (bold: environment v4, faint: v2)")
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=7)

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
