#pragma once
// What the server answers: maps a parsed request to a response (status line, headers, and a
// body that is either a view into a dataset's memory mapping — nodes, prefixes, file ranges are
// never copied — or a small owned string for JSON and errors). Also the request counters behind
// /stats and /metrics. Independent of the transport in server.cpp.
#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "datasets.h"
#include "http.h"
#include "log.h"

namespace catpaq::serve {

enum class Route : uint8_t { Index, Catalog, Dataset, Prefix, Node, Files, Stats, Metrics, Other };
constexpr size_t kRouteCount = 9;
const char* route_name(Route route);

// Status codes the counters keep apart; anything else is counted as "other".
constexpr std::array<int, 16> kCountedStatuses = {200, 204, 206, 304, 400, 404, 405, 408,
                                                  413, 414, 416, 431, 500, 501, 503, 505};
constexpr size_t kStatusSlots = kCountedStatuses.size() + 1;
size_t status_slot(int status);

// Counters of one I/O thread (written by it only; read by /stats from any thread).
struct alignas(64) WorkerStats {
    std::atomic<uint64_t> requests[kRouteCount][kStatusSlots] = {};
    std::atomic<uint64_t> bytes_sent{0};
};

struct ServerStats {
    std::vector<std::unique_ptr<WorkerStats>> workers;
    std::atomic<int64_t> open_connections{0};
    std::atomic<uint64_t> connections_accepted{0}, connections_refused{0}, timeouts{0};
    std::chrono::steady_clock::time_point started = std::chrono::steady_clock::now();
};

struct Response {
    int status = 200;
    Route route = Route::Other;
    bool close = false;      // close the connection after this response
    bool head_only = false;  // HEAD: the body is described by the headers but not sent
    int version_minor = 1;   // of the request (HTTP/1.0 keep-alive needs an explicit header)
    std::string head;        // status line, headers and the blank line
    const uint8_t* body = nullptr;  // view into a dataset mapping (lives as long as the server)
    size_t body_size = 0;
    std::string owned;  // body when body_owned
    bool body_owned = false;
    std::string log_request;  // "METHOD target" when request logging is on
    std::string log_note;
    std::chrono::steady_clock::time_point started;

    void reset();
    const uint8_t* body_data() const {
        return body_owned ? reinterpret_cast<const uint8_t*>(owned.data()) : body;
    }
    size_t wire_size() const { return head.size() + (head_only ? 0 : body_size); }
};

// Per-I/O-thread state the router needs: the cached Date header and that thread's counters.
struct WorkerContext {
    WorkerStats* stats = nullptr;
    std::string date;  // "Date: ...\r\n"
    int64_t date_second = -1;
    std::string scratch;  // decoded paths
    void refresh_date();
};

class Router {
public:
    Router(const Registry& registry, ServerStats& stats, const Logger& log);

    // Answers a well-framed request. `close`: the connection closes after this response (the
    // client asked, HTTP/1.0 without keep-alive, or the server is stopping).
    void handle(const http::Request& request, bool close, WorkerContext& context, Response& out) const;
    // Answers a request that could not be parsed (the connection then closes).
    void reject(int status, std::string_view message, WorkerContext& context, Response& out) const;
    // The preformatted 503 for connections over the limit.
    static std::string refusal();

    std::string stats_json() const;
    std::string metrics_text() const;

private:
    void error(int status, std::string_view message, Route route, bool close, bool head_only,
               WorkerContext& context, Response& out) const;
    void begin(int status, Route route, WorkerContext& context, Response& out) const;
    void finish(bool close, WorkerContext& context, Response& out) const;
    void node(const http::Request& request, const Dataset& dataset, std::string_view key_text, bool close,
              WorkerContext& context, Response& out) const;
    void file(const http::Request& request, const Dataset& dataset, bool close, WorkerContext& context,
              Response& out) const;

    const Registry& registry_;
    ServerStats& stats_;
    const Logger& log_;
};

}  // namespace catpaq::serve
