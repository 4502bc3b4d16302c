#pragma once
// Support for client_core_tests: a small CATP dataset (built once per process), residencies and
// cameras for the cut engine, and a tiny blocking HTTP/1.1 server that serves a .cpq the way
// `catpaq serve` does (prefix and node routes, and the raw file with Range support), with fault
// injection (errors, corrupt bytes, dropped connections, ignored ranges) and a gate that holds
// responses.
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "catp_client/catp_format.h"
#include "client/cut_engine.h"
#include "client/hierarchy.h"

namespace catpaq::test {

// A scratch directory for this process (removed at exit).
std::string scratch_dir();
// The sphere dataset used by the CATP tests (built on first use).
const std::string& sphere_dataset();
// The bytes of a whole file.
std::vector<uint8_t> read_file(const std::string& path);
// A local dataset's CATP format, opened from its prefix as a streaming session opens it.
std::unique_ptr<CatpFormat> open_catp_format(const std::string& path);
// A node of a local CATP dataset decoded by its format (as the fetcher's workers decode it).
std::shared_ptr<const DecodedNode> decode_catp_node(const CatpFormat& format, const CatpFile& file, uint32_t node);

// Everything resident, or only the nodes set so; bytes from primitives (gpu 16, cpu 20 per
// primitive), the same whether resident or not, so budgets are exact.
class FakeResidency : public Residency {
public:
    explicit FakeResidency(const Hierarchy& h, bool all_resident);
    bool resident(uint32_t node) const override { return resident_[node] != 0; }
    NodeBytes bytes(uint32_t node) const override;
    void set(uint32_t node, bool resident) { resident_[node] = resident; }
    size_t count() const;

private:
    const Hierarchy& h_;
    std::vector<uint8_t> resident_;
};

// Delivers every node the engine requests `delay` frames after the request (a fake fetcher).
class DelayedDelivery {
public:
    DelayedDelivery(FakeResidency& residency, int delay) : residency_(residency), delay_(delay) {}
    // Call once per frame after update(): records the new requests, drops cancelled ones, and
    // makes resident the ones whose time has come (visible to the next update()).
    void frame(const CutFrame& frame);
    size_t delivered() const { return delivered_; }

private:
    FakeResidency& residency_;
    int delay_;
    int64_t now_ = 0;
    std::map<uint32_t, int64_t> due_;
    size_t delivered_ = 0;
};

// A camera over the synthetic terrain ([0, size]^2, z ~ 0) or around a box.
ViewParams camera(const std::array<double, 3>& eye, const std::array<double, 3>& target, double tolerance = 1.5,
                  double fov_degrees = 60);

// A minimal blocking HTTP/1.1 server on 127.0.0.1 (one thread per connection, keep-alive).
//   GET /api/datasets/{name}/prefix, GET /api/datasets/{name}/nodes/{key}
//   GET /files/{name}.cpq with one `Range: bytes=a-b` (206), else 200 with the whole file.
class TestHttpServer {
public:
    enum class Fault { None, Status500, Corrupt, Close, Truncate };

    TestHttpServer(const std::string& file, const std::string& name);
    ~TestHttpServer();
    // Listens (on the same port as before after a stop(); a free port the first time).
    void start();
    // Stops accepting, closes every connection, joins the threads.
    void stop();
    bool running() const { return running_; }
    uint16_t port() const { return port_; }
    std::string base_url() const;  // http://127.0.0.1:PORT/api/datasets/NAME
    std::string file_url() const;  // http://127.0.0.1:PORT/files/NAME.cpq

    // The next `count` requests get these faults, in turn.
    void inject(int count, std::vector<Fault> cycle);
    void ignore_ranges(bool on) { ignore_ranges_ = on; }
    // While held, node and range answers wait (requests are still counted).
    void hold(bool on);

    size_t requests() const { return requests_; }
    size_t connections() const { return connections_; }
    std::vector<std::string> targets() const;
    size_t waiting() const { return waiting_; }  // requests held at the gate right now

private:
    void accept_loop();
    void serve(int fd);
    std::string answer(const std::string& method, const std::string& target, const std::string& range, bool& close);

    std::vector<uint8_t> file_;
    std::string name_;
    std::map<uint64_t, std::pair<uint64_t, uint64_t>> nodes_;  // key -> offset, size
    uint64_t prefix_size_ = 0;

    uint16_t port_ = 0;
    int listen_fd_ = -1;
    std::atomic<bool> running_{false};
    std::thread accept_thread_;
    std::mutex mutex_;
    std::condition_variable gate_;
    bool held_ = false;
    std::vector<std::thread> threads_;
    std::set<int> fds_;
    std::vector<std::string> targets_;
    std::vector<Fault> faults_;
    int fault_count_ = 0;
    size_t fault_index_ = 0;
    std::atomic<bool> ignore_ranges_{false};
    std::atomic<size_t> requests_{0}, connections_{0}, waiting_{0};
};

}  // namespace catpaq::test
