#!/usr/bin/env python3
"""A copy of a PPO checkpoint with its policy's log standard deviations set by hand: how the
rows "nothing trained" of docs/WORLDS.md ("Sampled actions") were made, to evaluate one
network's sampled actions at another noise (`crm eval` on the copy; the mean action is the
same). To train on from a noise, use `crm train --fine-tune FILE --init-log-std V` instead.

Usage: python3 scripts/set-log-std.py IN.safetensors OUT.safetensors VALUE [--from INDEX]
(needs numpy). VALUE goes to every action from INDEX on (default 0: all; the grasping machine's
actions are the palm's dx, dy, dz, then the five fingers', so `--from 3` sets the fingers').
Only the tensor `actor.log_std` changes; the header, the other weights and the observation
statistics are copied byte for byte.
"""
import argparse
import json
import struct
import sys

import numpy as np

TENSOR = "actor.log_std"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source")
    parser.add_argument("out")
    parser.add_argument("value", type=float)
    parser.add_argument("--from", dest="start", type=int, default=0)
    args = parser.parse_args()
    if not (np.isfinite(args.value) and -5.0 <= args.value <= 2.0):
        sys.exit(f"set-log-std: VALUE {args.value} must be in [-5, 2], as start_log_std")
    data = bytearray(open(args.source, "rb").read())
    if len(data) < 8:
        sys.exit(f"set-log-std: {args.source}: not a safetensors file (too short)")
    (size,) = struct.unpack("<Q", data[:8])
    try:
        header = json.loads(data[8 : 8 + size])
    except ValueError as err:
        sys.exit(f"set-log-std: {args.source}: not a safetensors file ({err})")
    entry = header.get(TENSOR)
    if entry is None or entry.get("dtype") != "F32":
        sys.exit(f"set-log-std: {args.source}: no F32 tensor {TENSOR} (a PPO checkpoint has one)")
    begin, end = (8 + size + offset for offset in entry["data_offsets"])
    log_std = np.frombuffer(bytes(data[begin:end]), dtype="<f4").copy()
    if not 0 <= args.start < len(log_std):
        sys.exit(f"set-log-std: --from {args.start}: the policy has {len(log_std)} actions")
    log_std[args.start :] = args.value
    data[begin:end] = log_std.astype("<f4").tobytes()
    open(args.out, "wb").write(data)
    print(f"{TENSOR}: {' '.join(f'{v:.4f}' for v in log_std)}")


if __name__ == "__main__":
    main()
