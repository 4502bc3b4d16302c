#!/usr/bin/env bash
# Newcomer command 1: set up, build, and run the main job on the bundled sample: convert the
# Stanford bunny to CATP, verify it, serve it on localhost, render views headless over HTTP, and
# print where the files are and the key figures; then the same bunny as AQP (quad patches) and as
# a point cloud, served by the same server and rendered by the same client. Everything it writes
# goes to out/ at the repository's root (out/*.cpq, out/serve.log, out/frames*/); a run replaces
# the previous one's.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/setup.sh"
"$root/scripts/build.sh" --target catpaq
bin="${BUILD_DIR:-$root/build}/apps/catpaq"
out="$root/out"
mkdir -p "$out"

echo
echo "== 1. convert data/bunny.ply -> out/bunny.cpq"
"$bin" convert "$root/data/bunny.ply" -o "$out/bunny.cpq"

echo
echo "== 2. verify out/bunny.cpq against the original"
"$bin" verify "$out/bunny.cpq" --mesh "$root/data/bunny.ply"

echo
echo "== 3. the same bunny as AQP (out/bunny_aqp.cpq) and as points (out/bunny_points.cpq)"
"$bin" convert "$root/data/bunny.ply" -o "$out/bunny_aqp.cpq" --format aqp --quiet
"$bin" verify "$out/bunny_aqp.cpq" --mesh "$root/data/bunny.ply" --quiet | tail -1
"$bin" convert "$root/data/bunny.ply" -o "$out/bunny_points.cpq" --format points --quiet 2>/dev/null
"$bin" verify "$out/bunny_points.cpq" --mesh "$root/data/bunny.ply" --quiet | tail -1
ls -l "$out"/bunny*.cpq | awk '{ printf "  %-40s %10d bytes\n", $NF, $5 }'

echo
echo "== 4. serve out/ on localhost"
log="$out/serve.log"
"$bin" serve --root "$out" --port 0 >"$log" 2>&1 &
server=$!
trap 'kill $server 2>/dev/null || true' EXIT
for _ in $(seq 1 100); do grep -q '^serving' "$log" && break; sleep 0.1; done
grep -q '^serving' "$log" || { echo "server did not start:"; cat "$log"; exit 1; }
url=$(grep -o 'http://[^ ]*' "$log" | head -1)
echo "server: $url  (catalog: ${url}api/datasets, log: $log)"

echo
echo "== 5. render 8 views headless over HTTP (streaming, 1.5 px tolerance)"
rm -rf "$out/frames"
"$bin" render "${url}api/datasets/bunny" --orbit 8 --up y --size 640x480 --out "$out/frames" \
  --stats "$out/frames/stats.jsonl" --export-cut "$out/frames/last_cut.ply" --quiet
# Key figures per frame from the statistics (docs/formats/stats.md), without anything but awk.
awk -F'[:,]' '
  BEGIN { printf "frame  triangles  fetched KiB  certified error (px)  tolerance met\n" }
  {
    for (i = 1; i < NF; i += 2) { k = $i; gsub(/[{}" ]/, "", k); v[k] = $(i + 1) }
    e = v["certified_error_px"] == "null" ? "not yet bounded" : sprintf("%.2f", v["certified_error_px"])
    printf "%5d %10d %12.1f %21s  %s\n", v["frame"], v["triangles"], v["bytes_fetched"] / 1024, e, v["tolerance_met"]
  }' "$out/frames/stats.jsonl"

echo
echo "== 6. AQP and points: 4 views each over HTTP, the same client"
for name in bunny_aqp bunny_points; do
  rm -rf "$out/frames_$name"
  "$bin" render "${url}api/datasets/$name" --orbit 4 --up y --size 640x480 --out "$out/frames_$name" \
    --stats "$out/frames_$name/stats.jsonl" --quiet
  awk -F'[:,]' -v name="$name" '
    { for (i = 1; i < NF; i += 2) { k = $i; gsub(/[{}" ]/, "", k); v[k] = $(i + 1) } }
    END { l = v["limited_by"]; gsub(/[\[\]"]/, "", l)
          printf "  %-13s last frame: %d triangles, %d points, %.1f KiB fetched, certified error %.2f px, tolerance met %s%s\n",
          name, v["triangles"], v["points"], v["bytes_fetched"] / 1024, v["certified_error_px"], v["tolerance_met"],
          l == "" ? "" : " (limited by " l ": the dataset holds nothing finer)" }
  ' "$out/frames_$name/stats.jsonl"
done

echo
echo "done:"
echo "  datasets   $out/bunny.cpq (CATP), $out/bunny_aqp.cpq (AQP), $out/bunny_points.cpq (points)"
echo "  frames     $out/frames/frame_*.png, $out/frames_bunny_aqp/, $out/frames_bunny_points/"
echo "  statistics $out/frames/stats.jsonl"
echo "  last cut   $out/frames/last_cut.ply"
