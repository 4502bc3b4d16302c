#!/usr/bin/env bash
# Newcomer command 1: set up, build, and run the main job on the bundled sample:
# convert the Stanford bunny to CATP, serve it on localhost, render views headless over HTTP,
# and print where the files are and the key figures.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/setup.sh"
"$root/scripts/build.sh"
bin="${BUILD_DIR:-$root/build}/apps/catpaq"
out="$root/out"
mkdir -p "$out"

echo
echo "== 1. convert data/bunny.ply -> out/bunny.cpq"
"$bin" convert "$root/data/bunny.ply" -o "$out/bunny.cpq"

if "$bin" --help | grep -q '^  verify'; then
  echo
  echo "== 2. verify out/bunny.cpq against the original"
  "$bin" verify "$out/bunny.cpq" --mesh "$root/data/bunny.ply"
fi

if "$bin" --help | grep -q '^  serve' && "$bin" --help | grep -q '^  render'; then
  echo
  echo "== 3. serve out/ on localhost and render views headless over HTTP"
  log="$out/serve.log"
  "$bin" serve --root "$out" --port 0 >"$log" 2>&1 &
  server=$!
  trap 'kill $server 2>/dev/null || true' EXIT
  for _ in $(seq 1 100); do grep -q '^serving' "$log" && break; sleep 0.1; done
  url=$(grep -o 'http://[^ ]*' "$log" | head -1)
  echo "server: $url (log: $log)"
  "$bin" render "${url}api/datasets/bunny" --orbit 8 --size 640x480 --out "$out/frames" --stats "$out/frames/stats.jsonl"
  echo "frames: $out/frames/ (PNG), statistics: $out/frames/stats.jsonl"
fi
echo
echo "done: outputs in $out"
