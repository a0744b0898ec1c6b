#!/usr/bin/env python3
"""A random search over a hand profile's free choices, judged by the scripted oracle.

usage: scripts/profile-search.py WORLD OUT.jsonl --seconds S [--workers N] [--seeds K]
                                 [--held JOINT=LO:HI ...] [--box X0:X1,Y0:Y1,Z0:Z1]
                                 [--torques T,T,...] [--topology NAME [--per-finger]
                                 [--preshape FINGER=LO:HI ...] [--fit]] [--keep-closed]

For each sample it writes a copy of WORLD's `hand.json` with the grasp point drawn from
`--box` (palm frame, m), each `--held` joint drawn from its range, the motors' torque from
`--torques` (default {0.2, 0.35, 0.5, 0.7} N m) and every topology's closed commands at 60%,
80% or 100% of each finger's range, runs `crm oracle --world COPY --json --seeds K`, and appends
the sample and its success to OUT.jsonl (one JSON line each). With `--topology NAME` the sample
is that topology's own (its `grasp_point`, `held` and `closed`; the torque stays the profile's)
and the oracle runs that topology's tasks only, and with `--per-finger` each of its fingers
closes to a fraction of its own (a pinch's thumb and index apart), and each `--preshape` finger
starts its closing from a command drawn from its range (rad; a finger's closed command is
never below it); with `--fit` each sample is judged after `crm world fit-grasps` has fitted
the topology's tasks' grasp locations to it (`--seeds` seeds each, rechecked on as many from
seed 200), for a shape that holds only a centimetre or more off the dataset's location, which
the oracle alone scores 0; with `--keep-closed` the profile's closed commands stay (a world
whose closing comes from its authors' data). The best line is a profile to try with more seeds.
`crm` is the release build (`CARGO_TARGET_DIR`, else `target/`); the description is found as
the world finds it (`CRM_ASSETS`). docs/WORLDS.md, "Bring your hand", has the Allegro search.
"""

import argparse
import json
import multiprocessing
import os
import random
import re
import shutil
import subprocess
import tempfile
import time

# How far the oracle closes a finger, as a fraction of its range.
CLOSING = [0.6, 0.8, 1.0]
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def crm_binary():
    target = os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target"))
    return os.path.join(target, "release", "crm")


def span(text, name):
    try:
        lo, hi = (float(v) for v in text.split(":"))
    except ValueError:
        raise SystemExit(f"{name}: expected LO:HI, got {text!r}")
    if not lo <= hi:
        raise SystemExit(f"{name}: LO must not exceed HI in {text!r}")
    return lo, hi


def named_spans(items, name):
    """`NAME=LO:HI` items as (NAME, "LO:HI") pairs, each span checked."""
    pairs = []
    for item in items:
        key, _, text = item.partition("=")
        span(text, name)
        pairs.append((key, text))
    return pairs


def sample(rng, args, fingers=()):
    box = [span(part, "--box") for part in args.box.split(",")]
    if len(box) != 3:
        raise SystemExit(f"--box: expected three LO:HI spans, got {args.box!r}")
    return {
        "grasp_point": [round(rng.uniform(*axis), 4) for axis in box],
        "held": {j: round(rng.uniform(*span(r, "--held")), 3) for j, r in args.held},
        "torque": rng.choice(args.torques),
        "close": {f: rng.choice(CLOSING) for f in fingers} if fingers else rng.choice(CLOSING),
        "preshape": {f: round(rng.uniform(*span(r, "--preshape")), 3) for f, r in args.preshape},
    }


def profile(base, world_dir, p):
    hand = json.loads(json.dumps(base))
    description = hand["description"]
    if not os.path.isabs(description) and os.path.exists(os.path.join(world_dir, description)):
        hand["description"] = os.path.join(world_dir, description)
    if p.get("topology"):
        shape = hand["topologies"][p["topology"]]
        shape["grasp_point"] = p["grasp_point"]
        shape["held"] = {**shape.get("held", {}), **p["held"]}
        shape["preshape"] = {**shape.get("preshape", {}), **p.get("preshape", {})}
        shapes = [shape]
    else:
        hand["grasp_point"] = p["grasp_point"]
        hand["held"] = {**hand.get("held", {}), **p["held"]}
        hand["motor"]["torque"] = p["torque"]
        shapes = hand["topologies"].values()
    for topology in shapes if p.get("close") else []:
        for finger in list(topology.get("closed", {})):
            lo, hi = hand["fingers"][finger]["range"]
            close = p["close"][finger] if isinstance(p["close"], dict) else p["close"]
            topology["closed"][finger] = round(lo + close * (hi - lo) * 0.999, 3)
    for topology in shapes:
        for finger, start in topology.get("preshape", {}).items():
            if finger in topology.get("closed", {}):
                topology["closed"][finger] = max(topology["closed"][finger], start)
    return hand


def benchmark_tasks(world_dir, world):
    """The world's tasks: its own benchmark file, or the built-in one."""
    path = os.path.join(world_dir, world.get("benchmark", ""))
    if not world.get("benchmark"):
        path = os.path.join(ROOT, "worlds", "crm", "benchmark.json")
    return json.load(open(path))["tasks"]


# A line of `crm world fit-grasps`'s progress: a task kept, or a task searched.
KEPT = re.compile(r"^(\S+): ([\d.]+) on the search seeds, kept")
FITTED = re.compile(r"^(\S+): ([\d.]+) -> ([\d.]+) on the search seeds, ([\d.]+) -> ([\d.]+) on the check seeds")


def fitted(scratch, tasks, seeds):
    """Success per task after `crm world fit-grasps` on the world in `scratch`: on the search
    seeds, and on the check seeds where the fit searched the task (None where it kept it)."""
    out = os.path.join(scratch, "fitted")
    done = subprocess.run(
        [crm_binary(), "world", "fit-grasps", scratch, "--out", out, "--seeds", str(seeds),
         "--check-seed", "200", "--check-seeds", str(seeds)]
        + [arg for task in tasks for arg in ("--task", task)],
        capture_output=True, text=True, timeout=3600)
    if done.returncode != 0:
        return None, done.stderr.strip()[-400:]
    result = {}
    for line in done.stderr.splitlines():
        if m := KEPT.match(line):
            result[m[1]] = {"search": float(m[2]), "check": None}
        elif m := FITTED.match(line):
            result[m[1]] = {"search": float(m[3]), "check": float(m[5])}
    return result, None


def run(job):
    index, args = job
    world_dir = os.path.abspath(args.world)
    world = json.load(open(os.path.join(world_dir, "world.json")))
    base = json.load(open(os.path.join(world_dir, world["hand"])))
    fingers = sorted(base["topologies"][args.topology]["closed"]) if args.topology and args.per_finger else ()
    p = sample(random.Random(index), args, fingers)
    tasks = []
    if args.keep_closed:
        p.pop("close")
    if not p["preshape"]:
        p.pop("preshape")
    if args.topology:
        p["topology"] = args.topology
        p.pop("torque")
        tasks = [t["id"] for t in benchmark_tasks(world_dir, world) if t["topology"] == args.topology]
    with tempfile.TemporaryDirectory() as scratch:
        for name in os.listdir(world_dir):
            if name != world["hand"]:
                source = os.path.join(world_dir, name)
                if os.path.isfile(source):
                    shutil.copy(source, scratch)
        json.dump(profile(base, world_dir, p), open(os.path.join(scratch, world["hand"]), "w"))
        if args.fit:
            result, error = fitted(scratch, tasks, args.seeds)
            if error is not None:
                return {"sample": index, "params": p, "error": error}
            return {"sample": index, "params": p,
                    "success": sum(r["search"] for r in result.values()) / max(len(result), 1),
                    "fitted": result}
        done = subprocess.run(
            [crm_binary(), "oracle", "--world", scratch, "--json", "--seeds", str(args.seeds)]
            + [arg for task in tasks for arg in ("--task", task)],
            capture_output=True, text=True, timeout=1800)
    if done.returncode != 0:
        return {"sample": index, "params": p, "error": done.stderr.strip()[-400:]}
    report = json.loads(done.stdout.strip().splitlines()[-1])
    return {"sample": index, "params": p, "success": report["success_rate"],
            "per_objective": {k: v["success_rate"] for k, v in report["per_objective"].items()}}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("world")
    parser.add_argument("out")
    parser.add_argument("--seconds", type=float, required=True)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--first", type=int, default=0, help="the first sample's seed")
    parser.add_argument("--box", default="0.0:0.1,-0.03:0.03,-0.1:0.03")
    parser.add_argument("--held", action="append", default=[], metavar="JOINT=LO:HI")
    parser.add_argument("--torques", default="0.2,0.35,0.5,0.7", help="motor torques to draw (N m)")
    parser.add_argument("--keep-closed", action="store_true", help="keep the profile's closed commands")
    parser.add_argument("--topology", help="search this topology's own grasp point, held joints and closing")
    parser.add_argument("--per-finger", action="store_true",
                        help="with --topology, draw each finger's closing on its own (a pinch's thumb and index)")
    parser.add_argument("--preshape", action="append", default=[], metavar="FINGER=LO:HI",
                        help="with --topology, draw this finger's preshape command (rad) from LO:HI")
    parser.add_argument("--fit", action="store_true",
                        help="with --topology, judge each sample after fitting its tasks' grasp locations")
    args = parser.parse_args()
    try:
        args.torques = [float(t) for t in args.torques.split(",")]
    except ValueError:
        raise SystemExit(f"--torques: expected numbers separated by commas, got {args.torques!r}")
    if not args.torques or any(not t > 0 for t in args.torques):
        raise SystemExit(f"--torques: each torque must be positive, got {args.torques!r}")
    args.held = named_spans(args.held, "--held")
    args.preshape = named_spans(args.preshape, "--preshape")
    if args.preshape and not args.topology:
        raise SystemExit("--preshape: needs --topology (the preshape drawn is that topology's)")
    if args.fit and not args.topology:
        raise SystemExit("--fit: needs --topology (the tasks fitted are that topology's)")
    if args.per_finger and not args.topology:
        raise SystemExit("--per-finger: needs --topology (the closing drawn is that topology's)")
    if args.per_finger and args.keep_closed:
        raise SystemExit("--per-finger: draws the closing that --keep-closed keeps; give one of them")
    if args.topology:
        world = json.load(open(os.path.join(args.world, "world.json")))
        hand = json.load(open(os.path.join(args.world, world["hand"])))
        if args.topology not in hand["topologies"]:
            raise SystemExit(f"--topology: {args.topology!r} is not one of {sorted(hand['topologies'])}")
        unknown = [f for f, _ in args.preshape if f not in hand["fingers"]]
        if unknown:
            raise SystemExit(f"--preshape: {unknown[0]!r} is not one of the hand's fingers {sorted(hand['fingers'])}")
        if not any(t["topology"] == args.topology for t in benchmark_tasks(args.world, world)):
            raise SystemExit(f"--topology: the world has no task with topology {args.topology!r}")
    start = time.time()
    with multiprocessing.Pool(args.workers) as pool, open(args.out, "w") as out:
        jobs = ((i, args) for i in range(args.first, args.first + 10**6))
        for result in pool.imap_unordered(run, jobs):
            out.write(json.dumps(result) + "\n")
            out.flush()
            if time.time() - start > args.seconds:
                pool.terminate()
                break


if __name__ == "__main__":
    main()
