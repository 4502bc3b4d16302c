#pragma once
// Getting node bytes: NodeSource (a local file or HTTP) and the asynchronous Fetcher.
//
// NodeSource is a non-blocking transfer interface (submit, poll, cancel) with blocking helpers
// on top. Two implementations:
//  - LocalFileSource: pread on a .cpq file.
//  - HttpSource: libcurl's multi interface, several transfers in parallel on persistent HTTP/1.1
//    connections. Two addressing modes, chosen from the URL:
//      server mode  base = http://host:port/api/datasets/NAME: GET {base}/prefix and
//                   GET {base}/nodes/{key} (catpaq serve, docs/http-api.md);
//      raw mode     a URL ending in .cpq (any static server: nginx, S3, `catpaq serve`'s /files/):
//                   Range: bytes=OFFSET-(OFFSET+SIZE-1); 206 with the exact range is required, a
//                   200 with the whole body is accepted only when the request covered the whole
//                   file.
//
// Fetcher runs a fetch thread: a priority queue of node requests (the cut engine's order each
// frame; stale requests cancelled), transfers on the source, every result checked against the
// index checksum (XXH3), decoded on worker threads by the dataset format's decoder (the fetcher
// knows byte ranges and checksums, not formats), and delivered through a completion queue the
// render thread polls without blocking. A request may name one part of a node (a byte range its
// format decodes and verifies alone, FetchRequest::part). Fetches queued at once whose byte
// ranges lie next to each other in the file (parts with parts, whole nodes with whole nodes)
// share one range transfer (FetcherSettings::coalesce_gap_bytes): small nodes listed together
// (AQP's tiles, CATP's slots) cost one request per run, not one each. A shared transfer
// is a plain byte range (server mode: the raw file route; one whole node alone still goes by
// key), cut into each fetch's slice, and each slice is verified alone (a whole node against its
// index checksum, a part by its format). A failed or corrupt fetch is retried with exponential
// backoff, in transfers of its own from then on (a bad node never fails its neighbours again;
// the fetches of a transfer that failed as a whole are all retried alone); after max_attempts
// the node is reported failed and retried later if still wanted.
// Connection errors (the server went away) are just failures: backoff, then success when it is
// back.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "client/format.h"
#include "client/hierarchy.h"

namespace catpaq {

// The first request (common_codec/archive.h): a raw file's first 64 KiB; a server's /prefix
// route answers with the prefix and what of level 0 fits in as much.
constexpr size_t kPrefixProbeBytes = kFirstRequestBytes;

struct SourceRequest {
    enum class Kind : uint8_t {
        Node,    // a node: server mode by key, else by range [offset, offset + size)
        Range,   // exactly the bytes [offset, offset + size)
        Prefix,  // the start of the file: server mode the whole prefix; else [0, size) clipped at the end
    };
    uint64_t id = 0;  // echoed in the result
    Kind kind = Kind::Node;
    uint64_t key = 0;
    uint64_t offset = 0;
    uint64_t size = 0;
};

struct SourceResult {
    uint64_t id = 0;
    bool ok = false;
    bool retryable = true;  // false for answers that will not change (404, 416, a range ignored)
    int http_status = 0;    // 0 for local files and transport errors
    std::string error;
    std::vector<uint8_t> bytes;
};

class NodeSource {
public:
    virtual ~NodeSource() = default;
    virtual std::string describe() const = 0;
    // Transfers the source runs at once; more submissions wait inside the source.
    virtual size_t max_parallel() const = 0;
    // The following three are called from one thread (the fetch thread, or a blocking helper).
    virtual void submit(const SourceRequest& request) = 0;
    // Drops a queued or running transfer; no result is reported for it.
    virtual void cancel(uint64_t id) = 0;
    // Advances transfers, waiting up to timeout_ms (0: not at all) for one to finish or for
    // wakeup(); appends the finished ones to `out`.
    virtual void poll(std::vector<SourceResult>& out, int timeout_ms) = 0;
    // Makes a concurrent poll() return early. Thread-safe.
    virtual void wakeup() = 0;
    virtual size_t in_flight() const = 0;  // submitted and not yet reported

    // Blocking helpers: one attempt, Error on failure. Not while a Fetcher owns the source.
    std::vector<uint8_t> fetch(SourceRequest request);
    std::vector<uint8_t> fetch_range(uint64_t offset, uint64_t size);
    std::vector<uint8_t> fetch_node(uint64_t key, uint64_t offset, uint64_t size);
};

class LocalFileSource : public NodeSource {
public:
    explicit LocalFileSource(const std::string& path);  // throws Error
    ~LocalFileSource() override;
    std::string describe() const override { return path_; }
    size_t max_parallel() const override { return 4; }
    void submit(const SourceRequest& request) override;
    void cancel(uint64_t id) override;
    void poll(std::vector<SourceResult>& out, int timeout_ms) override;
    void wakeup() override;
    size_t in_flight() const override;
    uint64_t file_size() const { return size_; }

private:
    std::string path_;
    int fd_ = -1;
    uint64_t size_ = 0;
    mutable std::mutex mutex_;
    std::condition_variable cv_;
    std::deque<SourceRequest> queue_;
    bool woken_ = false;
};

struct HttpSettings {
    size_t parallel = 6;              // transfers (and connections) at once
    long connect_timeout_ms = 3000;
    long transfer_timeout_ms = 30000;  // a whole transfer
    long low_speed_seconds = 10;       // abort below 1 byte/s for this long
};

class HttpSource : public NodeSource {
public:
    // `url`: a server base (…/api/datasets/NAME) or a raw file URL ending in .cpq.
    explicit HttpSource(const std::string& url, HttpSettings settings = {});
    ~HttpSource() override;
    std::string describe() const override { return url_; }
    size_t max_parallel() const override { return settings_.parallel; }
    void submit(const SourceRequest& request) override;
    void cancel(uint64_t id) override;
    void poll(std::vector<SourceResult>& out, int timeout_ms) override;
    void wakeup() override;
    size_t in_flight() const override;
    bool raw_mode() const { return raw_; }
    // Connections libcurl opened so far (persistent connections keep this small).
    uint64_t connections_opened() const { return connections_opened_; }

    struct Transfer;

private:
    void start_pending();
    void finish(Transfer* t, int curl_code, std::vector<SourceResult>& out);
    void collect(std::vector<SourceResult>& out);

    std::string url_;
    bool raw_ = false;
    HttpSettings settings_;
    void* multi_ = nullptr;  // CURLM*
    std::deque<SourceRequest> pending_;
    std::vector<std::unique_ptr<Transfer>> running_;
    std::vector<void*> idle_handles_;  // CURL*
    std::vector<SourceResult> ready_;  // answered without a transfer
    uint64_t connections_opened_ = 0;
};

// Opens a source for `location`: http:// or https:// → HttpSource, else a local file.
std::unique_ptr<NodeSource> open_node_source(const std::string& location, HttpSettings http = {});

// The prefix (header, metadata, index) of a dataset: the first kPrefixProbeBytes (server mode:
// the /prefix route), the header parsed, then the rest of the prefix if it is longer. The bytes
// returned may extend past the prefix (raw mode: the coarsest nodes). `attempts` tries with a
// short backoff between them; throws Error with the last problem.
std::vector<uint8_t> fetch_prefix(NodeSource& source, int attempts = 3);
// fetch_prefix, parsed (DatasetPrefix::parse): what a format is opened from.
DatasetPrefix load_prefix(NodeSource& source, int attempts = 3);

// What one fetch brings: a whole node, or one part of a node fetched by parts
// (HierarchyNode::fetch_parts).
constexpr uint8_t kWholeNode = 0xff;

// A node, or one of its parts, to fetch, from the hierarchy. `id` names the fetch (the
// fetcher's queue, cancel() and the caches go by it): the node key for a whole node, else
// part_fetch_id(). A part has no index checksum: its format's decoder verifies it (CATP: the
// fragment's own checksum).
struct FetchRequest {
    uint32_t node = kNoNode;
    uint64_t key = 0;  // the node's key
    uint8_t part = kWholeNode;  // index in HierarchyNode::parts
    uint64_t id = 0;
    uint64_t offset = 0;
    uint32_t size = 0;
    uint64_t checksum = 0;  // whole nodes: XXH3-64 from the index
    // For a node that decodes against its parent (HierarchyNode::decode_parent): that parent's
    // decoded data, held until the node is decoded (DatasetFormat::decode_with_parent).
    std::shared_ptr<const DecodedNode> decode_parent;

    static FetchRequest of(const HierarchyNode& node);
    static FetchRequest of_part(const HierarchyNode& node, size_t part);
};
// The fetch id of a part: bit 63 set (node keys of a hierarchy that fetches parts have it
// clear, Hierarchy::check), the node index and the part.
inline uint64_t part_fetch_id(uint32_t node, size_t part) { return (uint64_t(1) << 63) | (uint64_t(node) << 8) | part; }

struct FetchedNode {
    uint32_t node = kNoNode;
    uint64_t key = 0;
    uint8_t part = kWholeNode;
    uint64_t id = 0;  // FetchRequest::id
    bool ok = false;
    std::string error;  // !ok: the last problem; retried later if it is still requested
    uint32_t attempts = 0;
    std::shared_ptr<const std::vector<uint8_t>> compressed;  // the verified bytes
    std::shared_ptr<const DecodedNode> decoded;              // null when the fetcher has no decoder
};

// Decodes a node's verified bytes: an empty string and `out` set, or what is wrong (it may also
// throw). Called on the fetcher's worker threads, concurrently.
using NodeDecoder = std::function<std::string(const FetchRequest&, const uint8_t* data, size_t size,
                                              std::shared_ptr<const DecodedNode>& out)>;
// The decoder of a dataset's format (DatasetFormat::decode); the format must outlive the fetcher.
NodeDecoder format_decoder(const DatasetFormat& format);

struct FetcherSettings {
    size_t decode_threads = 2;
    std::chrono::milliseconds backoff_initial{50};
    std::chrono::milliseconds backoff_max{2000};
    uint32_t max_attempts = 6;                          // then reported failed
    std::chrono::milliseconds failed_retry_delay{5000};  // a failed node requested again waits this
    bool abort_stale_in_flight = false;  // stale transfers already running: finish (default) or abort
    // Fetches queued at once (whole nodes with whole nodes, parts with parts) whose byte ranges
    // lie within this many bytes of each other go in one transfer, up to max_coalesced_bytes:
    // fewer requests where nodes are small and listed together (AQP's finest tiles, stored by
    // level then tile along a Morton curve; one level's kd-tree nodes of a point cloud; a
    // diamond's slots that one parent creates, 4 bytes apart). 0: only touching ranges;
    // negative: never. Why 64, measured on cold starts of the 2M-triangle scan as AQP (the 6
    // views of RESULTS section 8, our server): 0 and 64 fetch exactly the bytes wanted (what
    // is queued together touches; the slots need 4); 256 fetched 1-11% more bytes for 0-36%
    // fewer requests, 1024 5-79% more (the gaps are unwanted patches) for 39-72% fewer, 4096
    // 2-2.8 times the bytes. Each request a larger gap saves costs some 500-600 bytes of
    // unwanted data, more than the request's own headers (about 350 bytes both ways), and the
    // requests run 6 at a time on persistent connections: exact bytes win.
    int64_t coalesce_gap_bytes = 64;
    uint64_t max_coalesced_bytes = uint64_t(1) << 20;
    // Decodes verified bytes (format_decoder(format)); empty: nodes are delivered as verified
    // bytes only.
    NodeDecoder decode;
};

struct FetcherStats {
    uint64_t transfers = 0;          // transfers started
    uint64_t bytes_fetched = 0;      // bytes received in successful transfers (coalesced ones
                                     // with the unrequested gaps between their fetches)
    uint64_t delivered = 0;          // nodes delivered decoded
    uint64_t transport_errors = 0;   // failed transfers (connection, HTTP status, short body),
                                     // one per transfer however many fetches it carried
    uint64_t checksum_failures = 0;  // bytes that did not match the index checksum
    uint64_t decode_failures = 0;
    uint64_t retries = 0;            // transfers started again after a failure
    uint64_t failed = 0;             // nodes reported failed after max_attempts
    uint64_t cancelled = 0;          // requests dropped as stale
    uint64_t supplied = 0;           // nodes decoded from bytes given by supply()
    size_t queued = 0, in_flight = 0, decoding = 0, waiting_retry = 0;
};

class Fetcher {
public:
    explicit Fetcher(std::unique_ptr<NodeSource> source, FetcherSettings settings = {});
    ~Fetcher();  // stops and joins the threads; undelivered results are dropped
    Fetcher(const Fetcher&) = delete;
    Fetcher& operator=(const Fetcher&) = delete;

    // The wanted nodes, best first (every frame, from the cut engine's requests): queued nodes
    // take the new order, new ones are queued, queued (or backing-off) nodes missing from the
    // list are cancelled as stale. Never blocks on I/O.
    void request(const std::vector<FetchRequest>& wanted);
    // Cancels these fetches, by FetchRequest::id (queued ones; running ones too when
    // abort_stale_in_flight).
    void cancel(const std::vector<uint64_t>& ids);
    // Bytes already at hand (a compressed cache): verified and decoded on the workers, delivered
    // like a fetched node.
    void supply(const FetchRequest& request, std::shared_ptr<const std::vector<uint8_t>> bytes);
    // Moves finished nodes (decoded, or failed) to `out`. Never blocks on I/O.
    size_t poll(std::vector<FetchedNode>& out);
    FetcherStats stats() const;
    // Nothing queued, running, decoding or waiting for a retry (finished nodes may still wait
    // for poll(); failed nodes waiting for a later retry do not count).
    bool idle() const;

private:
    enum class State : uint8_t { Queued, Running, Decoding, Backoff, Failed };
    struct Entry {
        FetchRequest request;
        State state = State::Queued;
        uint32_t attempts = 0;
        uint64_t transfer = 0;  // source id while Running
        bool alone = false;     // an attempt failed: fetched in transfers of its own from now on
        bool stale = false;
        bool wanted = true;
        std::chrono::steady_clock::time_point retry_at{};
        std::string last_error;
    };
    struct DecodeJob {
        FetchRequest request;
        std::shared_ptr<const std::vector<uint8_t>> bytes;
        uint32_t attempts = 0;
        bool supplied = false;
    };
    struct DecodeDone {
        FetchedNode node;
        bool corrupt = false;          // checksum or decode problem
        bool checksum_failed = false;
        bool supplied = false;
    };

    // A transfer's fetches: their ids in file order, and where the transfer's bytes start (a
    // transfer may carry several adjacent fetches, see gather()).
    struct Transfer {
        std::vector<uint64_t> ids;
        uint64_t offset = 0;
    };
    using CoalesceMap = std::map<std::pair<uint64_t, uint64_t>, Entry*>;  // (offset, id) -> queued entry

    void fetch_loop();
    void fetch_iterations();
    CoalesceMap coalescable(bool parts);
    Transfer gather(uint64_t head_id, const Entry& head, const CoalesceMap& queued, uint64_t& end) const;
    void decode_loop();
    uint64_t apply_commands();  // returns the command sequence number it saw
    void dispatch();
    void handle_result(SourceResult& r);
    void handle_decoded(DecodeDone& d);
    void fail_attempt(uint64_t key, const std::string& error, bool permanent);
    void deliver(FetchedNode node);
    void update_counts(uint64_t seq);

    std::unique_ptr<NodeSource> source_;
    FetcherSettings settings_;

    // Commands from the main thread.
    mutable std::mutex command_mutex_;
    bool has_wanted_ = false;
    std::vector<FetchRequest> wanted_;
    std::vector<uint64_t> cancels_;
    std::vector<DecodeJob> supplied_;
    uint64_t command_seq_ = 0, wanted_seq_ = 0;

    // Fetch-thread state.
    std::unordered_map<uint64_t, Entry> entries_;  // by key
    std::vector<uint64_t> order_;                  // keys, best first
    std::unordered_map<uint64_t, Transfer> transfer_key_;
    uint64_t next_transfer_ = 1;
    uint64_t stats_transfers_ = 0, stats_bytes_ = 0, stats_delivered_ = 0, stats_transport_errors_ = 0,
             stats_checksum_failures_ = 0, stats_decode_failures_ = 0, stats_retries_ = 0, stats_failed_ = 0,
             stats_cancelled_ = 0, stats_supplied_ = 0;

    // Decode workers.
    std::mutex decode_mutex_;
    std::condition_variable decode_cv_;
    std::deque<DecodeJob> decode_queue_;
    std::deque<DecodeDone> decoded_;

    // Completions for the main thread.
    mutable std::mutex done_mutex_;
    std::deque<FetchedNode> done_;
    // Recently delivered keys: kUnpolled until poll() hands them out, then the command sequence
    // number at that poll (lists issued up to it may still name them).
    static constexpr uint64_t kUnpolled = ~uint64_t(0);
    std::unordered_map<uint64_t, uint64_t> recent_;

    mutable std::mutex stats_mutex_;
    FetcherStats stats_;
    uint64_t applied_seq_ = 0;

    std::atomic<bool> stop_{false};
    std::vector<std::thread> workers_;
    std::thread fetch_thread_;
};

}  // namespace catpaq
