#!/usr/bin/env bash
# Load test of the coordinator on loopback with ApacheBench (`apt-get install apache2-utils`):
# REST round-trip latency of `GET /api/v1/jobs/1` and `GET /healthz`, and how many job
# submissions per second `POST /api/v1/jobs` sustains (each one validated and written to
# sqlite). Starts its own `crm-server` on a temporary data folder; prints the figures.
#   bash scripts/bench-service.sh [requests] [concurrency]
set -euo pipefail
cd "$(dirname "$0")/.."
requests="${1:-5000}"
concurrency="${2:-16}"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/crm-grasp-target}"
command -v ab >/dev/null || { echo "needs ab (apt-get install apache2-utils)" >&2; exit 1; }
cargo build --release -q -p crm-server
data="$(mktemp -d)"
port=$((20000 + RANDOM % 20000))
"$CARGO_TARGET_DIR/release/crm-server" --http "127.0.0.1:$port" --grpc 127.0.0.1:0 \
    --data-dir "$data" >/dev/null 2>"$data/log" &
server=$!
trap 'kill $server 2>/dev/null; rm -rf "$data"' EXIT
for _ in $(seq 50); do curl -sf "127.0.0.1:$port/healthz" >/dev/null && break; sleep 0.1; done
body="$data/job.json"
echo '{"kind": "train", "algorithm": "crm-ppo", "task": "mouse-press", "steps": 1000}' >"$body"
curl -sf -X POST "127.0.0.1:$port/api/v1/jobs" -H 'content-type: application/json' -d @"$body" >/dev/null

report() { # name, ab output
    local rps mean p50 p99
    rps=$(awk '/Requests per second/ {print $4}' <<<"$2")
    mean=$(awk '/Time per request:.*\(mean\)$/ {print $4}' <<<"$2")
    p50=$(awk '$1 == "50%" {print $2}' <<<"$2")
    p99=$(awk '$1 == "99%" {print $2}' <<<"$2")
    # ab counts responses whose length differs from the first as failed (job ids grow):
    # only connect, receive and exception failures are real.
    failed=$(awk '/Connect: .*Receive: .*Length: .*Exceptions:/ {gsub(/[(),]/, ""); print $2 + $4 + $8}' <<<"$2")
    non2xx=$(awk '/Non-2xx responses/ {print $3}' <<<"$2")
    printf '%-28s %9s req/s  mean %6s ms  p50 %4s ms  p99 %4s ms  failed %s  non-2xx %s\n' \
        "$1" "$rps" "$mean" "$p50" "$p99" "${failed:-0}" "${non2xx:-0}"
}
echo "crm-server on 127.0.0.1:$port, $requests requests, concurrency $concurrency, $(nproc) cores"
report "GET /healthz (c=1)" "$(ab -q -n "$requests" -c 1 "http://127.0.0.1:$port/healthz")"
report "GET /api/v1/jobs/1 (c=1)" "$(ab -q -n "$requests" -c 1 "http://127.0.0.1:$port/api/v1/jobs/1")"
report "GET /api/v1/jobs/1" "$(ab -q -n "$requests" -c "$concurrency" "http://127.0.0.1:$port/api/v1/jobs/1")"
report "POST /api/v1/jobs (c=1)" "$(ab -q -n "$requests" -c 1 -p "$body" -T application/json "http://127.0.0.1:$port/api/v1/jobs")"
report "POST /api/v1/jobs" "$(ab -q -n "$requests" -c "$concurrency" -p "$body" -T application/json "http://127.0.0.1:$port/api/v1/jobs")"
echo "jobs listed afterwards (limit 10000): $(curl -s "127.0.0.1:$port/api/v1/jobs?limit=10000" | grep -o '"kind":' | wc -l)"
