#!/usr/bin/env bash
# The dashboard screenshots in docs/dashboard/: starts `crm up` on a temporary data folder,
# trains a small experiment through the REST API (CRM-PPO with three seeds, LPPO with two,
# IPPO with one, on mouse-press; about ten minutes on two cores), evaluates every run and one
# checkpoint under each forced topology, then photographs each page in headless Chromium
# (`web/tests/screenshots.mjs`). Needs what the browser test needs (`npm ci --prefix web`,
# Debian's chromium).
#   bash scripts/dashboard-screenshots.sh [steps] [out-dir]
set -euo pipefail
cd "$(dirname "$0")/.."
steps="${1:-40000}"
out="${2:-docs/dashboard}"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/crm-grasp-target}"
cargo build --release -q -p crm-worker -p crm-server
data="$(mktemp -d)"
port=$((20000 + RANDOM % 20000))
"$CARGO_TARGET_DIR/release/crm" up --http "127.0.0.1:$port" --grpc "127.0.0.1:$((port + 1))" \
    --data-dir "$data" --workers 2 >"$data/log" 2>&1 &
up=$!
trap 'kill $up 2>/dev/null; wait $up 2>/dev/null || true; rm -rf "$data"' EXIT
base="http://127.0.0.1:$port"
for _ in $(seq 100); do curl -sf "$base/healthz" >/dev/null && break; sleep 0.2; done

submit() { curl -sf -X POST "$base/api/v1/jobs" -H 'content-type: application/json' -d "$1" | python3 -c 'import json, sys; print(json.load(sys.stdin)["id"])'; }
wait_all() { # ids...
    for id in "$@"; do
        while :; do
            state=$(curl -sf "$base/api/v1/jobs/$id" | python3 -c 'import json, sys; print(json.load(sys.stdin)["state"])')
            case "$state" in succeeded) break ;; failed|cancelled) echo "job $id $state" >&2; exit 1 ;; esac
            sleep 2
        done
    done
}
runs=()
for spec in "crm-ppo 0" "crm-ppo 1" "crm-ppo 2" "lppo 0" "lppo 1" "ippo 0"; do
    set -- $spec
    record=""
    [ "$1 $2" = "crm-ppo 0" ] && record=', "record": {"every": 25, "max_episodes": 4}'
    runs+=("$(submit "{\"kind\": \"train\", \"algorithm\": \"$1\", \"seed\": $2, \"task\": \"mouse-press\", \"steps\": $steps, \"envs\": 2, \"config\": {\"learning_rate\": 0.0003, \"rollout_steps\": 2048}$record}")")
done
wait_all "${runs[@]}"
evals=()
for id in "${runs[@]}"; do
    checkpoint=$(curl -sf "$base/api/v1/jobs/$id" | python3 -c 'import json, sys; print(json.load(sys.stdin)["result"]["checkpoint_id"])')
    evals+=("$(submit "{\"kind\": \"eval\", \"checkpoint_id\": $checkpoint, \"episodes\": 60, \"tasks\": [\"mouse-press\", \"stapler-press\", \"dispenser-press\", \"valve-twist\"]}")")
done
first=$(curl -sf "$base/api/v1/jobs/${runs[0]}" | python3 -c 'import json, sys; print(json.load(sys.stdin)["result"]["checkpoint_id"])')
for topology in task auto InSiAd2 pPdAb2 pPdAb23 pPdAb25 platform poPmAb25; do
    evals+=("$(submit "{\"kind\": \"eval\", \"checkpoint_id\": $first, \"episodes\": 40, \"tasks\": [\"mouse-press\", \"stapler-press\", \"valve-twist\", \"bottle-lift\"], \"topology\": \"$topology\", \"seed\": 1}")")
done
wait_all "${evals[@]}"
mkdir -p "$out"
node web/tests/screenshots.mjs "$base" "$out" "$(IFS=,; echo "${runs[*]}")"
echo "screenshots in $out"
