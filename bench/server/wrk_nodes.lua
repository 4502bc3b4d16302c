-- wrk script for bench/server/run.sh: fetches random nodes, the same sequence from every server.
--   MODE=node  : GET /api/datasets/$DATASET/nodes/KEY          (catpaq serve, httplib baseline)
--   MODE=range : GET /$FILE with "Range: bytes=FIRST-LAST"      (nginx serving the raw file)
-- LIST is the file written by server_bench_dataset: "key first last" per line. Keys stay strings
-- (they exceed 2^53). done() prints one RESULT line that run.sh parses.
local list = os.getenv("LIST") or error("LIST is not set")
local mode = os.getenv("MODE") or "node"
local dataset = os.getenv("DATASET") or "bench"
local file = os.getenv("FILE") or "bench.cpq"

local requests = {}

local thread_count = 0
function setup(thread)
  thread_count = thread_count + 1
  thread:set("id", thread_count)
end

-- Requests are formatted here, not at load time: wrk sets the Host header just before init().
function init(args)
  for line in io.lines(list) do
    local key, first, last = line:match("^(%d+) (%d+) (%d+)$")
    if key then
      if mode == "range" then
        requests[#requests + 1] = wrk.format("GET", "/" .. file, { Range = "bytes=" .. first .. "-" .. last })
      else
        requests[#requests + 1] = wrk.format("GET", "/api/datasets/" .. dataset .. "/nodes/" .. key)
      end
    end
  end
  math.randomseed(1000 + (id or 0))
end

function request()
  return requests[math.random(#requests)]
end

function done(summary, latency, _)
  local e = summary.errors
  io.write(string.format("RESULT requests=%d duration_us=%d bytes=%d p50_us=%d p99_us=%d errors=%d status_errors=%d\n",
    summary.requests, summary.duration, summary.bytes, latency:percentile(50), latency:percentile(99),
    e.connect + e.read + e.write + e.status + e.timeout, e.status))
end
