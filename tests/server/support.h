#pragma once
// Test support for the streaming server: small datasets built with ArchiveWriter (random node
// payloads, CATP meta), a temporary directory, an in-process server on a free port whose log
// lines are captured, and a tiny raw-socket HTTP/1.1 client (pipelining, malformed requests).
#include <cstdint>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "common_codec/archive.h"
#include "server/server.h"

namespace catpaq::test {

class TempDir {
public:
    TempDir();
    ~TempDir();
    const std::string& path() const { return path_; }

private:
    std::string path_;
};

struct NodeSpec {
    uint64_t key;
    uint16_t level;
    size_t size;
};

struct BuiltNode {
    uint64_t key = 0;
    uint16_t level = 0;
    std::vector<uint8_t> bytes;
};

// Writes an archive with the given nodes filled with random bytes (seeded). Catp archives get a
// CATP meta with `bounds_min/max`; other kinds get a few opaque meta bytes.
std::vector<BuiltNode> write_dataset(const std::string& path, ArchiveKind kind, const std::vector<NodeSpec>& nodes,
                                     uint32_t seed, const double bounds_min[3] = nullptr,
                                     const double bounds_max[3] = nullptr);
void flip_byte(const std::string& path, uint64_t offset);
std::string read_whole_file(const std::string& path);
void write_text_file(const std::string& path, const std::string& text);

// The standard fixture layout under root():
//   alpha.cpq            Catp, 40 nodes on 4 levels, sizes 0..40 KB, one empty and one 2 MiB node
//   sub/beta.cpq         Aqp, 6 nodes (no bounds)
//   inside_link.cpq      symlink to sub/beta.cpq (inside the root: served)
//   corrupt_node.cpq     Catp, 8 nodes, one payload byte of node kCorruptKey flipped
//   corrupt_header.cpq   header byte flipped: skipped at startup with a logged reason
//   fake.cpq             text, not a dataset: skipped
//   notes.txt            a non-dataset file inside the root
//   escape.cpq           symlink to ../outside/secret.cpq (outside the root: refused)
// and outside/secret.cpq, outside/secret.txt next to the root.
struct Fixture {
    static constexpr uint64_t kBigKey = 0x0300000000000008ull;
    static constexpr uint64_t kEmptyKey = 0x0100000000000002ull;
    static constexpr uint64_t kHugeKey = 0xF000000000000001ull;  // > 2^63: decimal parsing edge
    static constexpr uint64_t kCorruptKey = 0x0200000000000003ull;
    static constexpr double kMin[3] = {-1.5, 2.0, -3.25};
    static constexpr double kMax[3] = {10.0, 20.5, 30.0};

    Fixture();
    std::string root() const { return dir.path() + "/root"; }
    std::string outside() const { return dir.path() + "/outside"; }
    TempDir dir;
    std::vector<BuiltNode> alpha, beta, corrupt;
};

// Log lines captured from a server (thread-safe).
class LogCapture {
public:
    void add(LogLevel level, std::string_view line);
    std::vector<std::string> lines() const;
    bool contains(const std::string& a, const std::string& b = "") const;  // one line containing both

private:
    mutable std::mutex mutex_;
    std::vector<std::string> lines_;
};

// A started in-process server with captured logs. With `describe`, the datasets are described as
// `catpaq serve` describes them (builtin_dataset_describers) unless the settings give describers;
// without, the server knows no format at all.
struct RunningServer {
    explicit RunningServer(const std::string& root, ServerSettings settings = {}, bool describe = true);
    ~RunningServer();
    LogCapture log;
    std::unique_ptr<StreamingServer> server;
    uint16_t port = 0;
};

struct HttpResponse {
    int status = 0;
    std::string version;
    std::vector<std::pair<std::string, std::string>> headers;
    std::string body;
    bool has(const std::string& name) const;
    std::string header(const std::string& name) const;  // case-insensitive; "" if absent
};

class RawClient {
public:
    explicit RawClient(uint16_t port, int receive_buffer = 0);  // connects to 127.0.0.1
    ~RawClient();
    RawClient(const RawClient&) = delete;
    RawClient& operator=(const RawClient&) = delete;

    void send(const std::string& bytes);
    // Reads one response. `head`: the request was HEAD (no body follows). False if the connection
    // closed (or failed) before a complete response.
    bool read(HttpResponse& out, bool head = false);
    // Reads exactly n raw bytes (false on EOF/error).
    bool read_raw(size_t n, std::string& out);
    // Puts bytes back in front of what read() sees next.
    void unread(const std::string& bytes) { buffer_.insert(0, bytes); }
    // True if the server closes the connection (EOF or reset) before sending anything more.
    bool closed();
    // GET (or another method) with Host and the given extra header lines ("Name: value\r\n...").
    HttpResponse request(const std::string& method, const std::string& target, const std::string& headers = "");
    HttpResponse get(const std::string& target, const std::string& headers = "") {
        return request("GET", target, headers);
    }

private:
    bool fill();
    int fd_ = -1;
    std::string buffer_;
};

std::string request_text(const std::string& method, const std::string& target, const std::string& headers = "");
std::string to_string(const std::vector<uint8_t>& bytes);
std::string node_path(const std::string& dataset, uint64_t key);

}  // namespace catpaq::test

#include <gtest/gtest.h>

namespace catpaq::test {

// One fixture tree and one server (default settings, port 0, 2 threads) per test suite.
class ServerTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() {
        fixture = new Fixture;
        running = new RunningServer(fixture->root());
    }
    static void TearDownTestSuite() {
        delete running;
        delete fixture;
        running = nullptr;
        fixture = nullptr;
    }
    static uint16_t port() { return running->port; }
    static const BuiltNode& alpha_node(uint64_t key) {
        for (const BuiltNode& n : fixture->alpha)
            if (n.key == key) return n;
        throw std::runtime_error("no such fixture node");
    }
    inline static Fixture* fixture = nullptr;
    inline static RunningServer* running = nullptr;
};

}  // namespace catpaq::test
