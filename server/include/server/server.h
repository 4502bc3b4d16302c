#pragma once
// catpaq serve: one stateless HTTP/1.1 server for every converted dataset (*.cpq archives,
// common_codec/archive.h) under a root directory. It answers the JSON catalog, a dataset's prefix
// (header + meta + index), single nodes by key (checksum-verified, immutable, ETag'd) and raw file
// bytes with Range support, so the same client code runs against this server and a stock static
// server. It knows no dataset format: the catalog's per-format part comes from the describers
// it is given (server/describe.h). Routes, headers and status codes: docs/http-api.md.
//
// The HTTP library stays out of this header: tests start the server in-process on port 0 and talk
// to it over real sockets; `catpaq serve` calls run_server().
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "server/describe.h"

namespace catpaq {

enum class LogLevel { Error = 0, Warn = 1, Info = 2, Debug = 3 };
const char* log_level_name(LogLevel level);
// "error", "warn", "info" or "debug"; throws Error otherwise.
LogLevel parse_log_level(const std::string& text);

struct ServerSettings {
    std::string root;                 // directory scanned recursively for *.cpq datasets (required)
    std::string bind = "127.0.0.1";   // address to listen on (IPv4 or IPv6 literal)
    uint16_t port = 8080;             // 0: the kernel picks a free port; start() returns it
    int threads = 0;                  // I/O threads; 0: one per core
    int max_connections = 512;        // open client connections; excess ones get 503 and are closed
    double timeout_seconds = 10.0;    // a request must arrive (and a write make progress) within this
    LogLevel log_level = LogLevel::Info;  // Info logs one line per request
    size_t max_url_bytes = 8192;      // longer request targets get 414
    size_t max_header_bytes = 16384;  // larger header sections get 431
    size_t max_body_bytes = 65536;    // request bodies are read and discarded; larger ones get 413
    // Receives each log line (no trailing newline). Called from the I/O threads, possibly
    // concurrently. Empty: lines go to stderr.
    std::function<void(LogLevel, std::string_view)> log;
    // The catalog's per-format part (bounds, decoded metadata), by archive kind. Empty: every
    // dataset is served with its container's facts only.
    DatasetDescribers describers;
};

class StreamingServer {
public:
    explicit StreamingServer(ServerSettings settings);
    ~StreamingServer();  // stop() + wait()
    StreamingServer(const StreamingServer&) = delete;
    StreamingServer& operator=(const StreamingServer&) = delete;

    // Scans the root (corrupt datasets are logged and skipped), binds, starts the I/O threads and
    // returns the bound port without blocking. Throws Error (bad root, address in use, ...).
    uint16_t start();
    // Graceful shutdown, from any thread, idempotent: stops accepting, closes idle connections,
    // lets responses already being written finish, then the I/O threads exit.
    void stop();
    // Blocks until the I/O threads have exited (after stop()).
    void wait();

    uint16_t port() const;
    // Names of the datasets being served (valid after start()), sorted.
    std::vector<std::string> dataset_names() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Runs a server until SIGINT or SIGTERM, printing "serving N datasets on http://ADDR:PORT/" to
// stdout once it accepts connections. Returns the process exit code (0 after a graceful stop).
// Throws Error if the server cannot start.
int run_server(const ServerSettings& settings);

}  // namespace catpaq
