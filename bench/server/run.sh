#!/usr/bin/env bash
# Streaming server benchmark: `catpaq serve` vs nginx (and the cpp-httplib baseline) fetching
# random nodes of one dataset with wrk (keep-alive). Ours and the httplib baseline answer
# GET /api/datasets/bench/nodes/KEY (checksum-verified); nginx answers Range requests for the same
# nodes' bytes in the raw file (sendfile, open_file_cache, access_log off). Prints requests/s,
# p99 latency and errors side by side and the ratio ours/nginx (medians over ROUNDS rounds).
# Bounded: DURATION seconds per run.
#
#   bench/server/run.sh                      (needs the targets catpaq, server_bench_dataset,
#                                             server_bench_httplib built in $BUILD_DIR)
#   DURATION=10 ROUNDS=2 CONNECTIONS=100 THREADS=2 SERVER_THREADS=2 NODES=2000 HTTPLIB=1 bench/server/run.sh
# Total time: about ROUNDS * (2 or 3) * (DURATION + 1) seconds.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
here="$root/bench/server"
build="${BUILD_DIR:-$root/build}"
DURATION=${DURATION:-10}
CONNECTIONS=${CONNECTIONS:-100}
THREADS=${THREADS:-2}
SERVER_THREADS=${SERVER_THREADS:-2}
NODES=${NODES:-2000}
HTTPLIB=${HTTPLIB:-1}
ROUNDS=${ROUNDS:-2}
NGINX=${NGINX:-/usr/sbin/nginx}
catpaq="${CATPAQ:-$build/apps/catpaq}"
make_dataset="$build/bench/server/server_bench_dataset"
httplib_server="$build/bench/server/server_bench_httplib"

for tool in wrk curl python3 "$NGINX" "$catpaq" "$make_dataset"; do
  command -v "$tool" >/dev/null 2>&1 || { echo "run.sh: missing $tool (packages: scripts/setup.sh --bench; build: cmake --build $build --target catpaq server_bench_dataset server_bench_httplib)" >&2; exit 1; }
done

tmp=$(mktemp -d /tmp/catpaq-server-bench.XXXXXX)
chmod 755 "$tmp"  # nginx workers run as nobody
pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${pids[@]}"; do wait "$pid" 2>/dev/null || true; done
  rm -rf "$tmp"
}
trap cleanup EXIT

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
# Waits for "serving N datasets on http://ADDR:PORT/" in a log file and prints PORT.
wait_port() {
  for _ in $(seq 1 200); do
    if grep -q '^serving ' "$1" 2>/dev/null; then sed -n 's#^serving .* on http://.*:\([0-9]*\)/$#\1#p' "$1" | head -1; return; fi
    sleep 0.05
  done
  echo "run.sh: server did not start; log:" >&2; cat "$1" >&2; exit 1
}

mkdir -p "$tmp/data"
"$make_dataset" "$tmp/data/bench.cpq" "$tmp/list.txt" --nodes "$NODES" --min 4096 --max 40960 >/dev/null
chmod 644 "$tmp/data/bench.cpq"
echo "dataset: $NODES nodes of 4-40 KB, $(stat -c %s "$tmp/data/bench.cpq") bytes; wrk -t$THREADS -c$CONNECTIONS -d${DURATION}s; $(nproc) cores"

# Ours.
"$catpaq" serve --root "$tmp/data" --port 0 --threads "$SERVER_THREADS" --log-level warn >"$tmp/ours.log" 2>&1 &
pids+=($!)
ours_port=$(wait_port "$tmp/ours.log")

# nginx, same file, Range requests.
nginx_port=$(free_port)
mkdir -p "$tmp/nginx"
cat >"$tmp/nginx/nginx.conf" <<CONF
daemon off;
worker_processes $SERVER_THREADS;
pid $tmp/nginx/nginx.pid;
error_log $tmp/nginx/error.log warn;
events { worker_connections 4096; }
http {
  access_log off;
  sendfile on;
  tcp_nopush on;
  tcp_nodelay on;
  keepalive_requests 100000000;
  keepalive_timeout 65;
  open_file_cache max=64 inactive=60s;
  default_type application/octet-stream;
  client_body_temp_path $tmp/nginx/body;
  proxy_temp_path $tmp/nginx/proxy;
  fastcgi_temp_path $tmp/nginx/fastcgi;
  uwsgi_temp_path $tmp/nginx/uwsgi;
  scgi_temp_path $tmp/nginx/scgi;
  server {
    listen 127.0.0.1:$nginx_port;
    root $tmp/data;
    location / { }
  }
}
CONF
"$NGINX" -p "$tmp/nginx" -c "$tmp/nginx/nginx.conf" 2>"$tmp/nginx/stderr.log" &
pids+=($!)

httplib_port=""
if [ "$HTTPLIB" = 1 ] && [ -x "$httplib_server" ]; then
  # One pool thread per connection (+ spare): a keep-alive connection holds its thread.
  "$httplib_server" --file "$tmp/data/bench.cpq" --port 0 --threads $((CONNECTIONS + 8)) >"$tmp/httplib.log" 2>&1 &
  pids+=($!)
  httplib_port=$(wait_port "$tmp/httplib.log")
fi
for _ in $(seq 1 100); do curl -sf -o /dev/null "http://127.0.0.1:$nginx_port/bench.cpq" -r 0-0 && break; sleep 0.05; done

# Correctness first: the same nodes' bytes from every server.
mismatch=0
while read -r key first last; do
  curl -sf "http://127.0.0.1:$ours_port/api/datasets/bench/nodes/$key" -o "$tmp/a" || mismatch=1
  curl -sf -r "$first-$last" "http://127.0.0.1:$nginx_port/bench.cpq" -o "$tmp/b" || mismatch=1
  cmp -s "$tmp/a" "$tmp/b" || mismatch=1
  if [ -n "$httplib_port" ]; then
    curl -sf "http://127.0.0.1:$httplib_port/api/datasets/bench/nodes/$key" -o "$tmp/c" || mismatch=1
    cmp -s "$tmp/a" "$tmp/c" || mismatch=1
  fi
done < <(shuf -n 20 --random-source=<(yes) "$tmp/list.txt")
if [ "$mismatch" != 0 ]; then echo "run.sh: servers disagree on node bytes" >&2; exit 1; fi
echo "check: 20 random nodes byte-identical across servers"

# Runs wrk against one server and appends "name rps p50_ms p99_ms errors MiB/s" to results.txt.
measure() {  # name port mode
  local out="$tmp/wrk-$1.txt"
  LIST="$tmp/list.txt" MODE="$3" DATASET=bench FILE=bench.cpq \
    wrk -t1 -c10 -d1s -s "$here/wrk_nodes.lua" "http://127.0.0.1:$2" >/dev/null  # warm-up
  LIST="$tmp/list.txt" MODE="$3" DATASET=bench FILE=bench.cpq \
    wrk -t"$THREADS" -c"$CONNECTIONS" -d"${DURATION}s" --timeout 5s -s "$here/wrk_nodes.lua" "http://127.0.0.1:$2" >"$out"
  python3 - "$out" "$1" >>"$tmp/results.txt" <<'PY'
import re, sys
text = open(sys.argv[1]).read()
m = re.search(r"RESULT requests=(\d+) duration_us=(\d+) bytes=(\d+) p50_us=(\d+) p99_us=(\d+) errors=(\d+)", text)
if not m: sys.exit("no RESULT line in wrk output:\n" + text)
req, dur, byt, p50, p99, err = map(int, m.groups())
print(f"{sys.argv[2]} {req / (dur / 1e6):.0f} {p50 / 1000:.2f} {p99 / 1000:.2f} {err} {byt / (dur / 1e6) / 2**20:.0f}")
PY
}

# Rounds alternate the order so neither server always runs first on a shared machine.
for round in $(seq 1 "$ROUNDS"); do
  if [ $((round % 2)) = 1 ]; then order="ours nginx"; else order="nginx ours"; fi
  for who in $order; do
    if [ "$who" = ours ]; then measure ours "$ours_port" node; else measure nginx "$nginx_port" range; fi
  done
  if [ -n "$httplib_port" ]; then measure httplib "$httplib_port" node; fi
done

python3 - "$tmp/results.txt" <<'PY'
import statistics, sys
rows = [line.split() for line in open(sys.argv[1])]
labels = {"ours": "catpaq serve (nodes)", "nginx": "nginx (Range on file)", "httplib": "cpp-httplib (nodes)"}
print(f"\n{'run':<28} {'requests/s':>11} {'p50_ms':>8} {'p99_ms':>8} {'MiB/s':>7} {'errors':>7}")
for name, rps, p50, p99, err, mib in rows:
    print(f"{labels[name]:<28} {rps:>11} {p50:>8} {p99:>8} {mib:>7} {err:>7}")
med = {}
for name in labels:
    runs = [r for r in rows if r[0] == name]
    if runs:
        med[name] = (statistics.median(float(r[1]) for r in runs), statistics.median(float(r[3]) for r in runs),
                     sum(int(r[4]) for r in runs))
print(f"\n{'median over rounds':<28} {'requests/s':>11} {'p99_ms':>8} {'errors':>7}")
for name, (rps, p99, err) in med.items():
    print(f"{labels[name]:<28} {rps:>11.0f} {p99:>8.2f} {err:>7}")
o, n = med["ours"], med["nginx"]
print(f"\nratio ours/nginx: {o[0] / n[0]:.2f}x requests/s, {o[1] / n[1]:.2f}x p99 latency (lower is better)")
if "httplib" in med:
    print(f"ratio httplib/nginx: {med['httplib'][0] / n[0]:.2f}x requests/s")
if o[2]:
    sys.exit(f"run.sh: catpaq serve had {o[2]} errors")
PY
