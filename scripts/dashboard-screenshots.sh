#!/usr/bin/env bash
# The dashboard screenshots in docs/dashboard/: starts `crm up` on a temporary data folder
# (which registers the shipped model), trains a small experiment through the REST API as one
# sweep (CRM-PPO, LPPO and IPPO, two seeds each, on mouse-press; every final checkpoint
# evaluated; about ten minutes on two cores), evaluates one checkpoint under each forced
# topology and the shipped model once, then photographs each page in headless Chromium
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
sweep=$(curl -sf -X POST "$base/api/v1/sweeps" -H 'content-type: application/json' -d "{\"name\": \"mouse-press, three algorithms\", \"base\": {\"task\": \"mouse-press\", \"steps\": $steps, \"envs\": 2, \"config\": {\"learning_rate\": 0.0003, \"rollout_steps\": 2048}}, \"axes\": {\"algorithm\": [\"crm-ppo\", \"lppo\", \"ippo\"], \"seed\": [0, 1]}, \"eval\": {\"episodes\": 60, \"tasks\": [\"mouse-press\", \"stapler-press\", \"dispenser-press\", \"valve-twist\"]}}" | python3 -c 'import json, sys; print(json.load(sys.stdin)["sweep"]["id"])')
while :; do
    fraction=$(curl -sf "$base/api/v1/sweeps/$sweep" | python3 -c 'import json, sys; print(json.load(sys.stdin)["progress"]["fraction"])')
    [ "$fraction" = "1.0" ] && break
    sleep 5
done
mapfile -t runs < <(curl -sf "$base/api/v1/sweeps/$sweep" | python3 -c 'import json, sys; [print(j["id"]) for j in json.load(sys.stdin)["jobs"] if j["kind"] == "train"]')
evals=()
first=$(curl -sf "$base/api/v1/jobs/${runs[0]}" | python3 -c 'import json, sys; print(json.load(sys.stdin)["result"]["checkpoint_id"])')
for topology in task auto InSiAd2 pPdAb2 pPdAb23 pPdAb25 platform poPmAb25; do
    evals+=("$(submit "{\"kind\": \"eval\", \"checkpoint_id\": $first, \"episodes\": 40, \"tasks\": [\"mouse-press\", \"stapler-press\", \"valve-twist\", \"bottle-lift\"], \"topology\": \"$topology\", \"seed\": 1}")")
done
model=$(curl -sf "$base/api/v1/checkpoints?uploaded=true" | python3 -c 'import json, sys; print(json.load(sys.stdin)["checkpoints"][0]["id"])')
evals+=("$(submit "{\"kind\": \"eval\", \"checkpoint_id\": $model, \"episodes\": 100, \"seed\": 2}")")
wait_all "${evals[@]}"
mkdir -p "$out"
node web/tests/screenshots.mjs "$base" "$out" "$(IFS=,; echo "${runs[*]}")" "$sweep"
echo "screenshots in $out"
