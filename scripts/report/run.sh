#!/usr/bin/env bash
# Evaluation report: runs the catpaq tools, keeps their raw output in a temporary directory and
# lets report.py write docs/RESULTS.md and docs/results/*.png from it.
#
# Usage: scripts/report/run.sh [--short] [--out DIR]
#   --short    quick run (under 3 minutes on 2 cores; CI runs it from scripts/test.sh): build
#              bench on 100k triangles only, smaller generated meshes, render_bench bounded to
#              60 s (skipped with a stated reason if slower)
#   --out DIR  where RESULTS.md and results/*.png go (default: the repository's docs/)
# Environment: BUILD (default <repo>/build), PYTHON (default /usr/bin/python3, needs matplotlib),
#              KEEP_RAW=1 keeps the raw outputs (path printed at the end).
# Exit status: non-zero when a step the report needs fails (the failing step is named); optional
# sections (render_bench) degrade to a stated reason in the report instead.
set -euo pipefail

MODE=full
OUT=""
while [[ $# -gt 0 ]]; do
    case "$1" in
        --short) MODE=short ;;
        --out)
            [[ $# -ge 2 && -n "$2" ]] || { echo "run.sh: --out needs a directory" >&2; exit 2; }
            OUT="$2"; shift ;;
        --out=*) OUT="${1#--out=}" ;;
        -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
        *) echo "run.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
    esac
    shift
done

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
OUT="${OUT:-$ROOT/docs}"
mkdir -p "$OUT" || { echo "run.sh: cannot create --out directory $OUT" >&2; exit 2; }
OUT="$(cd "$OUT" && pwd)"
BUILD="${BUILD:-$ROOT/build}"
PYTHON="${PYTHON:-/usr/bin/python3}"
REPORT_PY="$ROOT/scripts/report/report.py"
WORK="$(mktemp -d /tmp/catpaq-report.XXXXXX)"
RAW="$WORK/raw"
mkdir -p "$RAW" "$WORK/root" "$WORK/rd" "$WORK/scanpaths"
SERVER_PID=""

cleanup() {
    local rc=$?
    if [[ -n "$SERVER_PID" ]] && kill -0 "$SERVER_PID" 2>/dev/null; then
        kill "$SERVER_PID" 2>/dev/null || true
        wait "$SERVER_PID" 2>/dev/null || true
    fi
    if [[ "${KEEP_RAW:-0}" == 1 ]]; then
        echo "raw outputs kept in $WORK" >&2
    else
        rm -rf "$WORK"
    fi
    exit $rc
}
trap cleanup EXIT
trap 'exit 130' INT TERM

log() { printf '[report %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

need() {  # need TARGET RELATIVE_PATH: build the binary if missing
    if [[ ! -x "$BUILD/$2" ]]; then
        log "building missing target $1"
        cmake --build "$BUILD" --target "$1" >&2
    fi
}
need catpaq apps/catpaq
need codec_bench bench/codec/codec_bench
need catp_build_bench bench/catp/catp_build_bench
need render_bench bench/client/render_bench
need hard_cases bench/catp/hard_cases
need rd_bench bench/catp/rd_bench
need gen_mesh bench/catp/gen_mesh
need memory_budget_bench bench/catp/memory_budget_bench
need fetch_bench bench/client/fetch_bench
need aqp_bench bench/aqp/aqp_bench
need points_bench bench/points/points_bench
need aqp_render_bench bench/client/aqp_render_bench

# required NAME OUTFILE CMD...: runs a step the report needs, output to OUTFILE; on failure names
# the step, shows the end of its output and stops the run (exit 1), so nothing half-measured is
# written.
required() {
    local name=$1 out=$2 rc=0
    shift 2
    "$@" > "$out" 2>&1 || rc=$?
    if [[ $rc -ne 0 ]]; then
        echo "run.sh: step '$name' failed (exit status $rc); end of its output:" >&2
        tail -n 25 "$out" >&2
        exit 1
    fi
}

CATPAQ="$BUILD/apps/catpaq"
BUNNY="$ROOT/data/bunny.ply"
T0=$(date +%s)

# ---- machine -------------------------------------------------------------------------------
{
    echo "mode: $MODE"
    echo "date: $(date -u '+%Y-%m-%d %H:%M:%S UTC')"
    echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
    echo "cores: $(nproc)"
    echo "kernel: $(uname -sr)"
    echo "memory: $(awk '/MemTotal/ {printf "%.1f GiB", $2/1048576}' /proc/meminfo)"
    echo "git: $(git -C "$ROOT" rev-parse --short HEAD 2>/dev/null || echo unknown)$(git -C "$ROOT" diff --quiet 2>/dev/null || echo ' (dirty)')"
} > "$RAW/machine.txt"

# ---- (1) rate-distortion -------------------------------------------------------------------
log "convert bunny"
s=$(date +%s%N)
required "convert bunny" "$RAW/convert.txt" "$CATPAQ" convert "$BUNNY" -o "$WORK/root/bunny.cpq" --quiet
e=$(date +%s%N)
echo "convert_seconds: $(( (e - s) / 1000000 ))e-3" >> "$RAW/machine.txt"
stat -c %s "$WORK/root/bunny.cpq" > "$RAW/dataset_size.txt"
required "info bunny" "$RAW/info.txt" "$CATPAQ" info "$BUNNY"

log "verify --mesh"
required "verify bunny" "$RAW/verify.txt" "$CATPAQ" verify "$WORK/root/bunny.cpq" --mesh "$BUNNY"

log "codec_bench"
required "codec_bench" "$RAW/codec_bench.txt" "$BUILD/bench/codec/codec_bench"

# The colored scan-like meshes (mesh/generators.h make_scan_like): one for rate-distortion, one
# (larger in the full run) for streaming. Short mode uses one 300k mesh for both.
if [[ $MODE == short ]]; then RD_TRIS=300000; STREAM_TRIS=300000; else RD_TRIS=1000000; STREAM_TRIS=2000000; fi
echo "rd_triangles: $RD_TRIS" >> "$RAW/machine.txt"
echo "stream_triangles: $STREAM_TRIS" >> "$RAW/machine.txt"
SCAN_RD="$WORK/scan_rd.ply"
log "gen_mesh scan $RD_TRIS"
required "gen_mesh scan $RD_TRIS" "$RAW/gen_scan_rd.txt" "$BUILD/bench/catp/gen_mesh" scan "$RD_TRIS" "$SCAN_RD"
log "convert scan ($RD_TRIS triangles)"
s=$(date +%s%N)
required "convert scan" "$RAW/convert_scan_rd.txt" "$CATPAQ" convert "$SCAN_RD" -o "$WORK/rd/scan.cpq" --quiet
e=$(date +%s%N)
echo "convert_scan_rd_seconds: $(( (e - s) / 1000000 ))e-3" >> "$RAW/machine.txt"
log "verify --mesh scan"
required "verify scan" "$RAW/verify_scan.txt" "$CATPAQ" verify "$WORK/rd/scan.cpq" --mesh "$SCAN_RD"

# Draco at several -qp and meshoptimizer at several position bit depths, measured with verify's
# distance code; our decode speed on the same datasets, in the same run.
log "rd_bench bunny"
required "rd_bench bunny" "$RAW/rd_bunny.txt" "$BUILD/bench/catp/rd_bench" "$BUNNY" --cpq "$WORK/root/bunny.cpq"
log "rd_bench scan"
required "rd_bench scan" "$RAW/rd_scan.txt" "$BUILD/bench/catp/rd_bench" "$SCAN_RD" --cpq "$WORK/rd/scan.cpq"
if [[ $MODE == full ]]; then
    log "codec_bench scan"
    required "codec_bench scan" "$RAW/codec_bench_scan.txt" "$BUILD/bench/codec/codec_bench" "$SCAN_RD"
fi

# ---- (2) build speed -----------------------------------------------------------------------
if [[ $MODE == short ]]; then SIZES=100000; else SIZES=100000,1000000,10000000; fi
log "catp_build_bench --sizes $SIZES"
required "catp_build_bench" "$RAW/build_bench.txt" "$BUILD/bench/catp/catp_build_bench" --sizes "$SIZES"

# ---- memory budget -------------------------------------------------------------------------
# Peaks measured from outside (wait4) from the smallest accepted budget upwards; a run past its
# budget fails the report.
if [[ $MODE == short ]]; then MB_TRIS=200000; MB_RUNS=2; MB_STEPS=0,32; else MB_TRIS=1000000; MB_RUNS=4; MB_STEPS=0,16,48; fi
log "memory_budget_bench scan $MB_TRIS"
required "memory_budget_bench scan" "$RAW/memory_scan.txt" "$BUILD/bench/catp/memory_budget_bench" \
    --triangles "$MB_TRIS" --threads 1,2 --steps "$MB_STEPS" --runs "$MB_RUNS"
log "memory_budget_bench uneven $MB_TRIS"
required "memory_budget_bench uneven" "$RAW/memory_uneven.txt" "$BUILD/bench/catp/memory_budget_bench" \
    --triangles "$MB_TRIS" --uneven --threads 1,2 --steps "$MB_STEPS" --runs "$MB_RUNS"

# ---- hard cases ----------------------------------------------------------------------------
# A case that neither passes nor is refused with a message fails the run.
log "hard cases"
required "hard_cases" "$RAW/hard_cases.txt" timeout 900 "$BUILD/bench/catp/hard_cases" --cuts 30

# ---- (3) streaming -------------------------------------------------------------------------
log "camera paths"
required "camera paths" "$RAW/paths.txt" "$PYTHON" "$REPORT_PY" paths --mesh "$BUNNY" --out "$WORK"

if [[ $STREAM_TRIS == "$RD_TRIS" ]]; then
    SCAN_STREAM="$SCAN_RD"
    cp "$WORK/rd/scan.cpq" "$WORK/root/scan.cpq"
    cp "$RAW/convert_scan_rd.txt" "$RAW/convert_scan_stream.txt"
else
    SCAN_STREAM="$WORK/scan_stream.ply"
    log "gen_mesh scan $STREAM_TRIS"
    required "gen_mesh scan $STREAM_TRIS" "$RAW/gen_scan_stream.txt" "$BUILD/bench/catp/gen_mesh" scan "$STREAM_TRIS" "$SCAN_STREAM"
    log "convert scan ($STREAM_TRIS triangles)"
    required "convert scan (streaming)" "$RAW/convert_scan_stream.txt" "$CATPAQ" convert "$SCAN_STREAM" -o "$WORK/root/scan.cpq" --quiet
fi
# The same mesh with finer nodes (500 instead of 2000 triangles per leaf fragment): how much of
# the cold-start cost of a close view is node granularity.
log "convert scan with --leaf-triangles 500"
required "convert scan (fine nodes)" "$RAW/convert_scan_fine.txt" "$CATPAQ" convert "$SCAN_STREAM" \
    -o "$WORK/root/scanfine.cpq" --leaf-triangles 500 --quiet
stat -c %s "$WORK/root/scanfine.cpq" > "$RAW/scanfine_dataset_size.txt"
required "verify scan (fine nodes)" "$RAW/verify_scan_fine.txt" "$CATPAQ" verify "$WORK/root/scanfine.cpq"
stat -c %s "$WORK/root/scan.cpq" > "$RAW/scan_dataset_size.txt"
required "verify scan (streaming)" "$RAW/verify_scan_stream.txt" "$CATPAQ" verify "$WORK/root/scan.cpq"
required "camera paths (scan)" "$RAW/paths_scan.txt" "$PYTHON" "$REPORT_PY" paths --mesh "$SCAN_STREAM" --out "$WORK/scanpaths" --kind scan
SCAN_PATHS="orbit zoom fly"

# Reference images: the same paths from the local file, tolerance 0.1 px, each frame converged
# (the finest level wherever it is visible).
for p in $SCAN_PATHS; do
    log "reference render scan $p (local, 0.1 px, converged)"
    required "reference render $p" "$RAW/ref_render_$p.txt" "$CATPAQ" render "$WORK/root/scan.cpq" \
        --camera-path "$WORK/scanpaths/path_$p.json" --tolerance 0.1 --timeout 600 \
        --stats "$RAW/ref_scan_$p.jsonl" --out "$WORK/ref_scan_$p"
done

# The same mesh as AQP, and its vertices as a point cloud: the three formats on the same views
# (section 8).
log "convert scan --format aqp"
s=$(date +%s%N)
required "convert scan aqp" "$RAW/convert_scan_aqp.json" "$CATPAQ" convert "$SCAN_STREAM" -o "$WORK/root/scanaqp.cpq" \
    --format aqp --json --quiet
e=$(date +%s%N)
echo "$(( (e - s) / 1000000 ))" > "$RAW/convert_scan_aqp_ms.txt"
# And AQP with one patch per node (no tiles): what tiles change on the same views.
log "convert scan --format aqp --tile-samples 0"
required "convert scan aqp untiled" "$RAW/convert_scan_aqp1.json" "$CATPAQ" convert "$SCAN_STREAM" \
    -o "$WORK/root/scanaqp1.cpq" --format aqp --tile-samples 0 --json --quiet
log "convert scan --format points"
s=$(date +%s%N)
required "convert scan points" "$RAW/convert_scan_points.json" "$CATPAQ" convert "$SCAN_STREAM" -o "$WORK/root/scanpts.cpq" \
    --format points --json --quiet
e=$(date +%s%N)
echo "$(( (e - s) / 1000000 ))" > "$RAW/convert_scan_points_ms.txt"
# What each needs before it draws the whole model (section 8's first frame).
for d in scan scanaqp scanaqp1 scanpts; do
    required "info $d" "$RAW/info_$d.txt" "$CATPAQ" info "$WORK/root/$d.cpq"
done

# Section 1.4's client measure: the rate-distortion scan served too (the streaming scan is a
# larger one in the full run).
cp "$WORK/rd/scan.cpq" "$WORK/root/scanrd.cpq"

log "serve"
"$CATPAQ" serve --root "$WORK/root" --port 0 --log-level warn > "$WORK/serve.log" 2>&1 &
SERVER_PID=$!
URL=""
for _ in $(seq 1 100); do
    URL=$(grep -o 'http://[0-9.]*:[0-9]*/' "$WORK/serve.log" 2>/dev/null | head -1 || true)
    [[ -n "$URL" ]] && break
    kill -0 "$SERVER_PID" 2>/dev/null || { cat "$WORK/serve.log" >&2; echo "server died" >&2; exit 1; }
    sleep 0.1
done
[[ -n "$URL" ]] || { echo "server did not start" >&2; exit 1; }
grep 'serving' "$WORK/serve.log" > "$RAW/serve.txt"
curl -fsS "${URL}api/datasets" > "$RAW/datasets.json" || echo '{}' > "$RAW/datasets.json"

# What a client fetches to show the finest level everywhere (section 1.4): the whole model in a
# 1600x1200 view at 0.05 px, so that every drawn node is a leaf; with the default level skipping
# (coarser levels drawn on the way) and skipping every level a refinement passes at once.
for d in bunny scanrd; do
    for skip in 8 1000000; do
        log "render $d, finest level everywhere, --skip $skip"
        required "finest $d skip $skip" "$RAW/finest_render_${d}_$skip.txt" "$CATPAQ" render "${URL}api/datasets/$d" \
            --orbit 1 --size 1600x1200 --tolerance 0.05 --skip "$skip" --timeout 300 --quiet \
            --stats "$RAW/finest_${d}_$skip.jsonl"
    done
done

for p in orbit zoom; do
    log "render $p over HTTP ($URL)"
    required "render $p" "$RAW/render_$p.txt" "$CATPAQ" render "${URL}api/datasets/bunny" \
        --camera-path "$WORK/path_$p.json" --size 640x480 --tolerance 1.5 --no-converge \
        --stats "$RAW/stream_$p.jsonl" --out "$WORK/frames_$p"
done
# A fresh client renders one view of a scan path until it converges: its stats and the whole
# command's wall time. cold_start DATASET PATH VIEW [SUFFIX EXTRA_OPTION...]
cold_start() {
    local dataset=$1 path=$2 view=$3 suffix=${4:-} s e
    shift 4 2>/dev/null || shift $#
    log "render $dataset $path $view view over HTTP (cold start, converged${suffix:+, $suffix})"
    s=$(date +%s%N)
    required "cold start $dataset $path $view $suffix" "$RAW/cold_render_${dataset}_${path}_$view$suffix.txt" "$CATPAQ" render \
        "${URL}api/datasets/$dataset" --camera-path "$WORK/scanpaths/path_${path}_$view.json" \
        --tolerance 1.5 --timeout 300 --stats "$RAW/cold_${dataset}_${path}_$view$suffix.jsonl" "$@"
    e=$(date +%s%N)
    echo "$(( (e - s) / 1000000 ))" > "$RAW/cold_${dataset}_${path}_${view}${suffix}_wall_ms.txt"
}

for p in $SCAN_PATHS; do
    # Progressive: one streaming step per frame from a cold start (fresh client, empty caches).
    log "render scan $p over HTTP (progressive)"
    required "render scan $p" "$RAW/render_scan_$p.txt" "$CATPAQ" render "${URL}api/datasets/scan" \
        --camera-path "$WORK/scanpaths/path_$p.json" --tolerance 1.5 --no-converge \
        --stats "$RAW/stream_scan_$p.jsonl" --out "$WORK/frames_scan_$p"
    # Cold start on the path's first view alone, and on its last view alone, waiting until it
    # converges: bytes and time to reach the tolerance (the whole command's wall time too).
    cold_start scan "$p" first
    cold_start scan "$p" last
    cold_start scanfine "$p" last
    # The same views fetching every level (no skipping) of whole diamonds: the first client.
    cold_start scan "$p" first _noskip --skip 0 --fetch-whole-nodes
    cold_start scan "$p" last _noskip --skip 0 --fetch-whole-nodes
    # And fetching whole diamonds instead of the slots a refinement draws: what parts save.
    cold_start scan "$p" first _whole --fetch-whole-nodes
    cold_start scan "$p" last _whole --fetch-whole-nodes
    # AQP and points on the same views.
    for view in first last; do
        cold_start scanaqp "$p" "$view"
        cold_start scanaqp1 "$p" "$view"
        cold_start scanpts "$p" "$view"
    done
    required "image error scan $p" "$RAW/imgerr_scan_$p.txt" "$PYTHON" "$REPORT_PY" compare \
        --ref "$WORK/ref_scan_$p" --frames "$WORK/frames_scan_$p" --out "$RAW/imgerr_scan_$p.jsonl"
done
kill "$SERVER_PID" 2>/dev/null || true
wait "$SERVER_PID" 2>/dev/null || true
SERVER_PID=""
# What each cold-start view draws, and the share of the finest level in its frustum.
VIEWS=()
for p in $SCAN_PATHS; do VIEWS+=("$WORK/scanpaths/path_${p}_first.json" "$WORK/scanpaths/path_${p}_last.json"); done
log "fetch_bench scan"
required "fetch_bench scan" "$RAW/fetch_bench_scan.txt" "$BUILD/bench/client/fetch_bench" "$WORK/root/scan.cpq" \
    "${VIEWS[@]}" --json "$RAW/fetch_bench_scan.jsonl"

# ---- (4) render throughput -----------------------------------------------------------------
log "render_bench"
set +e
if [[ $MODE == short ]]; then
    timeout 60 "$BUILD/bench/client/render_bench" > "$RAW/render_bench.txt" 2>&1
else
    "$BUILD/bench/client/render_bench" > "$RAW/render_bench.txt" 2>&1
fi
echo "$?" > "$RAW/render_bench_rc.txt"
set -e

# ---- (6) AQP beside CATP -------------------------------------------------------------------
# The AQP converter on the bunny and a scan-like mesh with the CATP converter on the same meshes
# in the same process (aqp_bench), and the bunny in AQP at its default finest level and one finer,
# measured against the original by verify as CATP is in (1).
if [[ $MODE == short ]]; then AQP_TRIS=200000; else AQP_TRIS=1000000; fi
log "aqp_bench --scan $AQP_TRIS"
required "aqp_bench" "$RAW/aqp_bench.txt" "$BUILD/bench/aqp/aqp_bench" --scan "$AQP_TRIS"
for level in default 5; do
    extra=(); [[ $level != default ]] && extra=(--patch-level "$level")
    log "convert bunny --format aqp ($level)"
    required "convert bunny aqp $level" "$RAW/aqp_bunny_$level.json" "$CATPAQ" convert "$BUNNY" \
        -o "$WORK/root/bunny_aqp_$level.cpq" --format aqp --json --quiet "${extra[@]}"
    log "verify --mesh bunny aqp ($level)"
    required "verify bunny aqp $level" "$RAW/aqp_verify_bunny_$level.txt" "$CATPAQ" verify \
        "$WORK/root/bunny_aqp_$level.cpq" --mesh "$BUNNY" --quiet
done

# A mesh above AQP's in-core budget: reduced out of core first (aqp/reduce.h), converted within
# --memory (the converter's peak from the kernel), and verified against the original file.
if [[ $MODE == short ]]; then OOC_TRIS=400000; OOC_MEM=150M; else OOC_TRIS=10000000; OOC_MEM=1G; fi
SCAN_OOC="$WORK/scan_ooc.ply"
log "gen_mesh scan $OOC_TRIS"
required "gen_mesh scan $OOC_TRIS" "$RAW/gen_scan_ooc.txt" "$BUILD/bench/catp/gen_mesh" scan "$OOC_TRIS" "$SCAN_OOC"
log "convert scan --format aqp --memory $OOC_MEM"
s=$(date +%s%N)
required "convert scan aqp out of core" "$RAW/aqp_ooc.json" "$CATPAQ" convert "$SCAN_OOC" -o "$WORK/aqp_ooc.cpq" \
    --format aqp --memory "$OOC_MEM" --json --quiet
e=$(date +%s%N)
echo "$(( (e - s) / 1000000 )) $OOC_MEM" > "$RAW/aqp_ooc_ms.txt"
log "verify --mesh scan aqp out of core"
required "verify scan aqp out of core" "$RAW/aqp_ooc_verify.txt" "$CATPAQ" verify "$WORK/aqp_ooc.cpq" --mesh "$SCAN_OOC" \
    --quiet
rm -f "$SCAN_OOC" "$WORK/aqp_ooc.cpq"

# AQP's client against CATP's on the same mesh, in one GL context: decode throughput of the level
# chains, and sessions converged on the same views (triangles, GPU bytes, fetched, frame time).
log "aqp_render_bench"
required "aqp_render_bench" "$RAW/aqp_render_bench.txt" "$BUILD/bench/client/aqp_render_bench"

# ---- (7) points ----------------------------------------------------------------------------
# The point converter and codec on random samples of the scan-like surface (points_bench: each
# conversion in a child process for its own peak memory; meshoptimizer as the same-run baseline).
# Full mode goes up to 100M points (about 12 minutes and 7 GiB for that size alone), and converts
# that cloud again out of core at --memory 1G (about 5 minutes). --laz: the first cloud as LAZ at
# the leaves' grid step, decoded by laz-perf (scripts/report/laz_decode.mjs) in the same run.
if [[ $MODE == short ]]; then PT_SIZES=200000; PT_RUNS=2; PT_BUDGETS=(); else
    PT_SIZES=1000000,10000000,100000000; PT_RUNS=5; PT_BUDGETS=(--budgets 1G); fi
log "points_bench --sizes $PT_SIZES ${PT_BUDGETS[*]}"
required "points_bench" "$RAW/points_bench.txt" "$BUILD/bench/points/points_bench" --sizes "$PT_SIZES" \
    --decode-runs "$PT_RUNS" --laz "${PT_BUDGETS[@]}"

T1=$(date +%s)
echo "total_seconds: $((T1 - T0))" >> "$RAW/machine.txt"

# ---- write the report ----------------------------------------------------------------------
log "report.py"
required "report.py write" "$RAW/report_py.txt" "$PYTHON" "$REPORT_PY" write --raw "$RAW" --work "$WORK" --docs "$OUT"
log "done in $((T1 - T0)) s: $OUT/RESULTS.md"
