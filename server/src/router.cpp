#include "router.h"

#include <charconv>
#include <ctime>

#include <nlohmann/json.hpp>

namespace catpaq::serve {

using nlohmann::json;

namespace {

// Sent with every response: a browser page on any origin may fetch and read these.
constexpr std::string_view kCommonHeaders =
    "Server: catpaq\r\n"
    "Access-Control-Allow-Origin: *\r\n"
    "Access-Control-Expose-Headers: Content-Length, Content-Range, ETag, Accept-Ranges\r\n";
constexpr std::string_view kAllow = "GET, HEAD, OPTIONS";
constexpr std::string_view kImmutable = "Cache-Control: public, max-age=31536000, immutable\r\n";
constexpr std::string_view kNoCache = "Cache-Control: no-cache\r\n";
constexpr std::string_view kOctets = "Content-Type: application/octet-stream\r\n";
constexpr std::string_view kJson = "Content-Type: application/json\r\n";

void append_number(std::string& s, uint64_t v) {
    char buffer[24];
    auto result = std::to_chars(buffer, buffer + sizeof buffer, v);
    s.append(buffer, size_t(result.ptr - buffer));
}

void content_length(std::string& s, uint64_t v) {
    s += "Content-Length: ";
    append_number(s, v);
    s += "\r\n";
}

bool starts_with(std::string_view s, std::string_view prefix) { return s.substr(0, prefix.size()) == prefix; }

}  // namespace

const char* route_name(Route route) {
    switch (route) {
        case Route::Index: return "index";
        case Route::Catalog: return "catalog";
        case Route::Dataset: return "dataset";
        case Route::Prefix: return "prefix";
        case Route::Node: return "node";
        case Route::Files: return "files";
        case Route::Stats: return "stats";
        case Route::Metrics: return "metrics";
        case Route::Other: return "other";
    }
    return "other";
}

size_t status_slot(int status) {
    for (size_t i = 0; i < kCountedStatuses.size(); ++i)
        if (kCountedStatuses[i] == status) return i;
    return kCountedStatuses.size();
}

void Response::reset() {
    status = 200;
    route = Route::Other;
    close = head_only = body_owned = false;
    version_minor = 1;
    head.clear();
    body = nullptr;
    body_size = 0;
    owned.clear();
    log_request.clear();
    log_note.clear();
}

void WorkerContext::refresh_date() {
    int64_t now = int64_t(std::time(nullptr));
    if (now != date_second) {
        date_second = now;
        date = http::date_header(now);
    }
}

Router::Router(const Registry& registry, ServerStats& stats, const Logger& log)
    : registry_(registry), stats_(stats), log_(log) {}

void Router::begin(int status, Route route, WorkerContext& context, Response& out) const {
    out.status = status;
    out.route = route;
    std::string& h = out.head;
    h.reserve(512);
    h += "HTTP/1.1 ";
    append_number(h, uint64_t(status));
    h += ' ';
    h += http::status_reason(status);
    h += "\r\n";
    h += context.date;
    h += kCommonHeaders;
}

void Router::finish(bool close, WorkerContext& context, Response& out) const {
    out.close = close;
    if (close) out.head += "Connection: close\r\n";
    else if (out.version_minor == 0) out.head += "Connection: keep-alive\r\n";
    out.head += "\r\n";
    context.stats->requests[size_t(out.route)][status_slot(out.status)].fetch_add(1, std::memory_order_relaxed);
}

void Router::error(int status, std::string_view message, Route route, bool close, bool head_only,
                   WorkerContext& context, Response& out) const {
    begin(status, route, context, out);
    out.owned = json{{"status", status}, {"error", message}}.dump(-1, ' ', false, json::error_handler_t::replace);
    out.owned += '\n';
    out.body_owned = true;
    out.body_size = out.owned.size();
    out.head_only = head_only;
    out.log_note = message;
    out.head += kJson;
    out.head += kNoCache;
    content_length(out.head, out.body_size);
    if (status == 405) {
        out.head += "Allow: ";
        out.head += kAllow;
        out.head += "\r\n";
    }
    finish(close, context, out);
}

void Router::reject(int status, std::string_view message, WorkerContext& context, Response& out) const {
    error(status, message, Route::Other, true, false, context, out);
}

std::string Router::refusal() {
    std::string body = "{\"status\":503,\"error\":\"too many open connections\"}\n";
    std::string s = "HTTP/1.1 503 Service Unavailable\r\nServer: catpaq\r\nAccess-Control-Allow-Origin: *\r\n"
                    "Content-Type: application/json\r\nRetry-After: 1\r\nConnection: close\r\nContent-Length: ";
    s += std::to_string(body.size());
    s += "\r\n\r\n";
    s += body;
    return s;
}

void Router::handle(const http::Request& req, bool close, WorkerContext& context, Response& out) const {
    out.version_minor = req.version_minor;
    const bool get = req.method == "GET", head = req.method == "HEAD", options = req.method == "OPTIONS";
    if (req.target == "*") {
        if (!options) return error(400, "'*' is only a target for OPTIONS", Route::Other, close, head, context, out);
        begin(204, Route::Other, context, out);
        out.head += "Allow: GET, HEAD, OPTIONS\r\n";
        return finish(close, context, out);
    }
    std::string why;
    std::string_view path;
    if (!http::decode_target(req.target, context.scratch, path, why))
        return error(400, why, Route::Other, close, head, context, out);

    // Route with a hand-written matcher (no regular expressions on the hot path).
    Route route = Route::Other;
    const Dataset* dataset = nullptr;
    std::string_view key_text;
    constexpr std::string_view kDatasets = "/api/datasets/", kFiles = "/files/", kNodes = "/nodes/",
                               kPrefix = "/prefix";
    if (starts_with(path, kDatasets)) {
        std::string_view rest = path.substr(kDatasets.size());
        // An exact dataset name wins, then "<name>/prefix", then "<name>/nodes/<key>".
        if ((dataset = registry_.by_name(rest))) {
            route = Route::Dataset;
        } else if (rest.size() > kPrefix.size() && rest.substr(rest.size() - kPrefix.size()) == kPrefix &&
                   (dataset = registry_.by_name(rest.substr(0, rest.size() - kPrefix.size())))) {
            route = Route::Prefix;
        } else if (size_t at = rest.rfind(kNodes); at != std::string_view::npos &&
                                                   (dataset = registry_.by_name(rest.substr(0, at)))) {
            route = Route::Node;
            key_text = rest.substr(at + kNodes.size());
        } else {
            return error(404, "no such dataset or dataset route", Route::Other, close, head, context, out);
        }
    } else if (starts_with(path, kFiles)) {
        dataset = registry_.by_file(path.substr(kFiles.size()));
        if (!dataset) return error(404, "no such dataset file", Route::Files, close, head, context, out);
        route = Route::Files;
    } else if (path == "/api/datasets") {
        route = Route::Catalog;
    } else if (path == "/stats") {
        route = Route::Stats;
    } else if (path == "/metrics") {
        route = Route::Metrics;
    } else if (path == "/") {
        route = Route::Index;
    } else {
        return error(404, "no such route", Route::Other, close, head, context, out);
    }

    if (options) {  // CORS preflight
        begin(204, route, context, out);
        out.head += "Allow: GET, HEAD, OPTIONS\r\n"
                    "Access-Control-Allow-Methods: GET, HEAD, OPTIONS\r\n";
        out.head += "Access-Control-Allow-Headers: ";
        out.head += req.access_control_request_headers.empty() ? std::string_view("Range, If-None-Match, If-Range")
                                                               : req.access_control_request_headers;
        out.head += "\r\nAccess-Control-Max-Age: 86400\r\n";
        return finish(close, context, out);
    }
    if (!get && !head) return error(405, "method not allowed", route, close, false, context, out);
    out.head_only = head;

    switch (route) {
        case Route::Node: return node(req, *dataset, key_text, close, context, out);
        case Route::Files: return file(req, *dataset, close, context, out);
        case Route::Prefix: {
            if (!req.if_none_match.empty() && http::etag_list_matches(req.if_none_match, dataset->prefix_etag)) {
                begin(304, route, context, out);
            } else {
                begin(200, route, context, out);
                out.body = dataset->reader->data();
                out.body_size = dataset->first_request_size;
                out.head += kOctets;
                content_length(out.head, out.body_size);
            }
            out.head += "ETag: ";
            out.head += dataset->prefix_etag;
            out.head += "\r\n";
            out.head += kNoCache;
            return finish(close, context, out);
        }
        default: break;
    }

    // JSON routes.
    const std::string* body = nullptr;
    switch (route) {
        case Route::Catalog: body = &registry_.catalog_json(); break;
        case Route::Dataset: body = &dataset->details_json; break;
        case Route::Stats: out.owned = stats_json(); break;
        case Route::Metrics: out.owned = metrics_text(); break;
        default:
            out.owned = R"({"service":"catpaq","catalog":"/api/datasets","stats":"/stats","metrics":"/metrics"})";
            break;
    }
    begin(200, route, context, out);
    if (body) {
        out.body = reinterpret_cast<const uint8_t*>(body->data());
        out.body_size = body->size();
    } else {
        out.body_owned = true;
        out.body_size = out.owned.size();
    }
    out.head += route == Route::Metrics ? "Content-Type: text/plain; version=0.0.4; charset=utf-8\r\n" : kJson;
    out.head += kNoCache;
    content_length(out.head, out.body_size);
    finish(close, context, out);
}

void Router::node(const http::Request& req, const Dataset& d, std::string_view key_text, bool close,
                  WorkerContext& context, Response& out) const {
    uint64_t key = 0;
    if (!http::parse_node_key(key_text, key))
        return error(400, "node key must be a decimal or 0x-prefixed hexadecimal 64-bit integer", Route::Node, close,
                     out.head_only, context, out);
    auto it = d.by_key.find(key);
    if (it == d.by_key.end()) return error(404, "no such node in this dataset", Route::Node, close, out.head_only,
                                           context, out);
    const ArchiveEntry& entry = d.reader->entries()[it->second];
    char etag[19];
    etag[0] = '"';
    std::string hex = http::hex64(entry.checksum);
    std::copy(hex.begin(), hex.end(), etag + 1);
    etag[17] = '"';
    std::string_view tag(etag, 18);
    if (!req.if_none_match.empty() && http::etag_list_matches(req.if_none_match, tag)) {
        begin(304, Route::Node, context, out);
    } else {
        std::string problem;
        const uint8_t* bytes = d.reader->node(it->second, &problem);
        if (!bytes) {
            log_.logf(LogLevel::Error, "refusing to send a corrupt node: %s", problem.c_str());
            return error(500, "node " + std::to_string(key) + " of dataset '" + d.name +
                                  "' is corrupt on the server (checksum mismatch)",
                         Route::Node, close, out.head_only, context, out);
        }
        begin(200, Route::Node, context, out);
        out.body = bytes;
        out.body_size = entry.size;
        out.head += kOctets;
        content_length(out.head, entry.size);
    }
    out.head += "ETag: ";
    out.head += tag;
    out.head += "\r\n";
    out.head += kImmutable;
    finish(close, context, out);
}

void Router::file(const http::Request& req, const Dataset& d, bool close, WorkerContext& context,
                  Response& out) const {
    const uint64_t size = d.reader->size();
    if (!req.if_none_match.empty() && http::etag_list_matches(req.if_none_match, d.etag)) {
        begin(304, Route::Files, context, out);
    } else {
        http::RangeResult range = http::RangeResult::None;
        uint64_t first = 0, last = 0;
        // If-Range: ranges apply only to the representation the client has (strong comparison).
        if (!req.range.empty() && (req.if_range.empty() || req.if_range == d.etag))
            range = http::parse_range(req.range, size, first, last);
        if (range == http::RangeResult::Unsatisfiable) {
            error(416, "requested range not satisfiable", Route::Files, close, out.head_only, context, out);
            // error() finished the head; add Content-Range before its blank line.
            out.head.insert(out.head.size() - 2, "Content-Range: bytes */" + std::to_string(size) + "\r\n");
            return;
        }
        if (range == http::RangeResult::Single) {
            begin(206, Route::Files, context, out);
            out.head += "Content-Range: bytes ";
            append_number(out.head, first);
            out.head += '-';
            append_number(out.head, last);
            out.head += '/';
            append_number(out.head, size);
            out.head += "\r\n";
        } else {
            begin(200, Route::Files, context, out);
            first = 0;
            last = size - 1;
        }
        out.body = d.reader->data() + first;
        out.body_size = size_t(last - first + 1);
        out.head += kOctets;
        content_length(out.head, out.body_size);
    }
    out.head += "Accept-Ranges: bytes\r\nETag: ";
    out.head += d.etag;
    out.head += "\r\n";
    finish(close, context, out);
}

namespace {

struct Totals {
    uint64_t requests[kRouteCount][kStatusSlots] = {};
    uint64_t bytes_sent = 0, total = 0;
};

Totals totals(const ServerStats& stats) {
    Totals t;
    for (const auto& w : stats.workers) {
        for (size_t r = 0; r < kRouteCount; ++r)
            for (size_t s = 0; s < kStatusSlots; ++s) {
                uint64_t n = w->requests[r][s].load(std::memory_order_relaxed);
                t.requests[r][s] += n;
                t.total += n;
            }
        t.bytes_sent += w->bytes_sent.load(std::memory_order_relaxed);
    }
    return t;
}

std::string status_label(size_t slot) {
    return slot < kCountedStatuses.size() ? std::to_string(kCountedStatuses[slot]) : "other";
}

double uptime(const ServerStats& stats) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - stats.started).count();
}

}  // namespace

std::string Router::stats_json() const {
    Totals t = totals(stats_);
    json requests = json::object();
    for (size_t r = 0; r < kRouteCount; ++r) {
        json by_status = json::object();
        for (size_t s = 0; s < kStatusSlots; ++s)
            if (t.requests[r][s]) by_status[status_label(s)] = t.requests[r][s];
        if (!by_status.empty()) requests[route_name(Route(r))] = std::move(by_status);
    }
    json j{{"uptime_seconds", uptime(stats_)},
           {"datasets", registry_.datasets().size()},
           {"open_connections", stats_.open_connections.load()},
           {"connections_accepted", stats_.connections_accepted.load()},
           {"connections_refused", stats_.connections_refused.load()},
           {"timeouts", stats_.timeouts.load()},
           {"bytes_sent", t.bytes_sent},
           {"requests_total", t.total},
           {"requests", std::move(requests)}};
    return j.dump() + "\n";
}

std::string Router::metrics_text() const {
    Totals t = totals(stats_);
    std::string s;
    auto metric = [&](const char* name, const char* type, const char* help) {
        s += "# HELP ";
        s += name;
        s += ' ';
        s += help;
        s += "\n# TYPE ";
        s += name;
        s += ' ';
        s += type;
        s += '\n';
    };
    metric("catpaq_requests_total", "counter", "HTTP requests answered, by route and status code.");
    for (size_t r = 0; r < kRouteCount; ++r)
        for (size_t s_ = 0; s_ < kStatusSlots; ++s_)
            if (t.requests[r][s_])
                s += std::string("catpaq_requests_total{route=\"") + route_name(Route(r)) + "\",status=\"" +
                     status_label(s_) + "\"} " + std::to_string(t.requests[r][s_]) + "\n";
    metric("catpaq_bytes_sent_total", "counter", "Bytes written to clients (headers and bodies).");
    s += "catpaq_bytes_sent_total " + std::to_string(t.bytes_sent) + "\n";
    metric("catpaq_open_connections", "gauge", "Client connections open now.");
    s += "catpaq_open_connections " + std::to_string(stats_.open_connections.load()) + "\n";
    metric("catpaq_connections_accepted_total", "counter", "Client connections accepted.");
    s += "catpaq_connections_accepted_total " + std::to_string(stats_.connections_accepted.load()) + "\n";
    metric("catpaq_connections_refused_total", "counter", "Connections refused (503) over the connection limit.");
    s += "catpaq_connections_refused_total " + std::to_string(stats_.connections_refused.load()) + "\n";
    metric("catpaq_timeouts_total", "counter", "Connections closed because a request or write timed out.");
    s += "catpaq_timeouts_total " + std::to_string(stats_.timeouts.load()) + "\n";
    metric("catpaq_datasets", "gauge", "Datasets being served.");
    s += "catpaq_datasets " + std::to_string(registry_.datasets().size()) + "\n";
    metric("catpaq_uptime_seconds", "gauge", "Seconds since the server started.");
    char buffer[64];
    std::snprintf(buffer, sizeof buffer, "%.3f", uptime(stats_));
    s += std::string("catpaq_uptime_seconds ") + buffer + "\n";
    return s;
}

}  // namespace catpaq::serve
