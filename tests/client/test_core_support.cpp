#include "test_core_support.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "catp/builder.h"
#include "common_codec/archive.h"
#include "mesh/generators.h"
#include "scratch_directory.h"

namespace catpaq::test {

namespace fs = std::filesystem;

std::string scratch_dir() {
    static const ScratchDirectory dir("catpaq_client_core_");
    return dir.string();
}

const std::string& sphere_dataset() {
    static std::string path = [] {
        std::string p = scratch_dir() + "/sphere.cpq";
        CatpBuildSettings settings;
        settings.leaf_triangles = 150;
        settings.progress = false;
        build_catp(make_sphere(40000, 3), p, settings);
        return p;
    }();
    return path;
}

std::vector<uint8_t> read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error("cannot read " + path);
    return std::vector<uint8_t>((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

std::unique_ptr<CatpFormat> open_catp_format(const std::string& path) {
    std::vector<uint8_t> bytes = read_file(path);
    return std::make_unique<CatpFormat>(DatasetPrefix::parse(bytes.data(), bytes.size(), path));
}

std::shared_ptr<const DecodedNode> decode_catp_node(const CatpFormat& format, const CatpFile& file, uint32_t node) {
    const HierarchyNode& n = format.hierarchy().node(node);
    std::string error;
    const uint8_t* bytes = file.archive().node(n.entry, &error);
    if (!bytes) throw std::runtime_error(error);
    std::shared_ptr<const DecodedNode> out;
    error = format.decode(node, bytes, n.payload_bytes, out);
    if (!error.empty()) throw std::runtime_error(error);
    return out;
}

// ---------------------------------------------------------------------------------------------

FakeResidency::FakeResidency(const Hierarchy& h, bool all_resident) : h_(h), resident_(h.size(), all_resident ? 1 : 0) {}

NodeBytes FakeResidency::bytes(uint32_t node) const {
    const HierarchyNode& n = h_.node(node);
    if (!n.has_data) return {};
    return {uint64_t(n.primitives) * 16, uint64_t(n.primitives) * 20 + 64};
}

size_t FakeResidency::count() const {
    size_t c = 0;
    for (uint8_t r : resident_) c += r;
    return c;
}

void DelayedDelivery::frame(const CutFrame& frame) {
    now_++;
    for (const CutRequest& c : frame.cancelled) due_.erase(c.node);
    for (const CutRequest& r : frame.requests)
        if (!due_.count(r.node)) due_[r.node] = now_ + delay_;
    for (auto it = due_.begin(); it != due_.end();) {
        if (it->second <= now_) {
            residency_.set(it->first, true);
            delivered_++;
            it = due_.erase(it);
        } else {
            ++it;
        }
    }
}

ViewParams camera(const std::array<double, 3>& eye, const std::array<double, 3>& target, double tolerance,
                  double fov_degrees) {
    std::array<double, 3> f{target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]};
    double l = std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
    std::array<double, 3> up{0, 0, 1};
    if (std::fabs(f[2]) > 0.99 * l) up = {0, 1, 0};
    ViewParams v = ViewParams::look_at(eye, target, up, fov_degrees * M_PI / 180.0, 800, 600, 0.05, 1e7);
    v.tolerance_px = tolerance;
    return v;
}

// ---------------------------------------------------------------------------------------------
// TestHttpServer

TestHttpServer::TestHttpServer(const std::string& file, const std::string& name) : file_(read_file(file)), name_(name) {
    ArchiveHeader header;
    std::string problem = parse_archive_header(file_.data(), file_.size(), header);
    if (!problem.empty()) throw std::runtime_error(problem);
    std::vector<ArchiveEntry> entries;
    problem = parse_archive_index(header, file_.data() + header.index_offset, header.index_size, entries);
    if (!problem.empty()) throw std::runtime_error(problem);
    for (const ArchiveEntry& e : entries) nodes_[e.key] = {e.offset, e.size};
    prefix_size_ = header.index_offset + header.index_size;
}

TestHttpServer::~TestHttpServer() { stop(); }

void TestHttpServer::start() {
    if (running_) return;
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (listen_fd_ < 0) throw std::runtime_error("socket");
    int one = 1;
    ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    addr.sin_port = htons(port_);
    if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0)
        throw std::runtime_error(std::string("bind: ") + std::strerror(errno));
    if (::listen(listen_fd_, 64) != 0) throw std::runtime_error("listen");
    socklen_t len = sizeof(addr);
    ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
    port_ = ntohs(addr.sin_port);
    running_ = true;
    accept_thread_ = std::thread([this] { accept_loop(); });
}

void TestHttpServer::stop() {
    if (!running_) return;
    running_ = false;
    accept_thread_.join();
    ::close(listen_fd_);
    listen_fd_ = -1;
    std::vector<std::thread> threads;
    {
        std::lock_guard<std::mutex> lock(mutex_);
        for (int fd : fds_) ::shutdown(fd, SHUT_RDWR);
        gate_.notify_all();
        threads.swap(threads_);
    }
    for (std::thread& t : threads) t.join();
}

std::string TestHttpServer::base_url() const {
    return "http://127.0.0.1:" + std::to_string(port_) + "/api/datasets/" + name_;
}

std::string TestHttpServer::file_url() const {
    return "http://127.0.0.1:" + std::to_string(port_) + "/files/" + name_ + ".cpq";
}

void TestHttpServer::inject(int count, std::vector<Fault> cycle) {
    std::lock_guard<std::mutex> lock(mutex_);
    fault_count_ = count;
    faults_ = std::move(cycle);
    fault_index_ = 0;
}

void TestHttpServer::hold(bool on) {
    std::lock_guard<std::mutex> lock(mutex_);
    held_ = on;
    gate_.notify_all();
}

std::vector<std::string> TestHttpServer::targets() const {
    std::lock_guard<std::mutex> lock(const_cast<std::mutex&>(mutex_));
    return targets_;
}

void TestHttpServer::accept_loop() {
    while (running_) {
        pollfd p{listen_fd_, POLLIN, 0};
        if (::poll(&p, 1, 20) <= 0) continue;
        int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
        if (fd < 0) continue;
        std::lock_guard<std::mutex> lock(mutex_);
        fds_.insert(fd);
        connections_++;
        threads_.emplace_back([this, fd] { serve(fd); });
    }
}

namespace {

bool send_all(int fd, const char* data, size_t size) {
    while (size > 0) {
        ssize_t n = ::send(fd, data, size, MSG_NOSIGNAL);
        if (n <= 0) return false;
        data += n;
        size -= size_t(n);
    }
    return true;
}

std::string lower(std::string s) {
    for (char& c : s) c = char(std::tolower((unsigned char)c));
    return s;
}

}  // namespace

void TestHttpServer::serve(int fd) {
    std::string buffer;
    bool close_after = false;
    while (running_ && !close_after) {
        size_t end;
        while ((end = buffer.find("\r\n\r\n")) == std::string::npos) {
            pollfd p{fd, POLLIN, 0};
            int r = ::poll(&p, 1, 20);
            if (!running_) goto done;
            if (r <= 0) continue;
            char chunk[4096];
            ssize_t n = ::recv(fd, chunk, sizeof(chunk), 0);
            if (n <= 0) goto done;
            buffer.append(chunk, size_t(n));
        }
        {
            std::string head = buffer.substr(0, end);
            buffer.erase(0, end + 4);
            size_t line_end = head.find("\r\n");
            std::string request_line = head.substr(0, line_end);
            std::string method = request_line.substr(0, request_line.find(' '));
            size_t t0 = request_line.find(' ') + 1;
            std::string target = request_line.substr(t0, request_line.find(' ', t0) - t0);
            std::string range;
            size_t pos = line_end;
            while (pos != std::string::npos && pos < head.size()) {
                size_t next = head.find("\r\n", pos + 2);
                std::string line = head.substr(pos + 2, (next == std::string::npos ? head.size() : next) - pos - 2);
                size_t colon = line.find(':');
                if (colon != std::string::npos) {
                    std::string name = lower(line.substr(0, colon));
                    std::string value = line.substr(colon + 1);
                    while (!value.empty() && value.front() == ' ') value.erase(0, 1);
                    if (name == "range") range = value;
                    if (name == "connection" && lower(value) == "close") close_after = true;
                }
                pos = next;
            }
            Fault fault = Fault::None;
            {
                std::lock_guard<std::mutex> lock(mutex_);
                targets_.push_back(target);
                if (fault_count_ > 0 && !faults_.empty()) {
                    fault = faults_[fault_index_++ % faults_.size()];
                    fault_count_--;
                }
            }
            requests_++;
            if (fault == Fault::Close) goto done;
            bool gated = target.find("/nodes/") != std::string::npos || target.rfind("/files/", 0) == 0;
            if (gated) {
                std::unique_lock<std::mutex> lock(mutex_);
                if (held_) {
                    waiting_++;
                    gate_.wait(lock, [&] { return !held_ || !running_; });
                    waiting_--;
                }
                if (!running_) goto done;
            }
            std::string response = answer(method, target, range, close_after);
            size_t header_end = response.find("\r\n\r\n") + 4;
            if (fault == Fault::Status500) {
                std::string body = "{\"status\":500,\"error\":\"injected\"}";
                response = "HTTP/1.1 500 Internal Server Error\r\nContent-Length: " + std::to_string(body.size()) +
                           "\r\nContent-Type: application/json\r\n\r\n" + body;
            } else if (fault == Fault::Corrupt && response.size() > header_end) {
                response[header_end + (response.size() - header_end) / 2] ^= 0x5a;
            } else if (fault == Fault::Truncate && response.size() > header_end + 1) {
                response.resize(header_end + (response.size() - header_end) / 2);
                send_all(fd, response.data(), response.size());
                goto done;
            }
            if (!send_all(fd, response.data(), response.size())) goto done;
        }
    }
done:
    std::lock_guard<std::mutex> lock(mutex_);
    fds_.erase(fd);
    ::close(fd);
}

std::string TestHttpServer::answer(const std::string& method, const std::string& target, const std::string& range,
                                   bool& close) {
    auto respond = [&](int status, const char* reason, const std::string& body, const std::string& extra = "") {
        std::string r = "HTTP/1.1 " + std::to_string(status) + " " + reason + "\r\nContent-Length: " +
                        std::to_string(body.size()) + "\r\nContent-Type: application/octet-stream\r\n" + extra +
                        (close ? "Connection: close\r\n" : "") + "\r\n";
        if (method != "HEAD") r += body;
        return r;
    };
    auto bytes = [&](uint64_t offset, uint64_t size) {
        return std::string(reinterpret_cast<const char*>(file_.data()) + offset, size);
    };
    std::string api = "/api/datasets/" + name_ + "/";
    if (target.rfind(api, 0) == 0) {
        std::string rest = target.substr(api.size());
        if (rest == "prefix") return respond(200, "OK", bytes(0, prefix_size_));
        if (rest.rfind("nodes/", 0) == 0) {
            char* end = nullptr;
            uint64_t key = std::strtoull(rest.c_str() + 6, &end, 10);
            auto it = nodes_.find(key);
            if (*end == 0 && it != nodes_.end()) return respond(200, "OK", bytes(it->second.first, it->second.second));
        }
        return respond(404, "Not Found", "");
    }
    if (target == "/files/" + name_ + ".cpq") {
        uint64_t size = file_.size();
        unsigned long long a = 0, b = 0;
        if (!range.empty() && !ignore_ranges_ && std::sscanf(range.c_str(), "bytes=%llu-%llu", &a, &b) == 2) {
            if (a > b || a >= size) return respond(416, "Range Not Satisfiable", "", "Content-Range: bytes */" + std::to_string(size) + "\r\n");
            b = std::min<unsigned long long>(b, size - 1);
            return respond(206, "Partial Content", bytes(a, b - a + 1),
                           "Content-Range: bytes " + std::to_string(a) + "-" + std::to_string(b) + "/" +
                               std::to_string(size) + "\r\n");
        }
        return respond(200, "OK", bytes(0, size));
    }
    return respond(404, "Not Found", "");
}

}  // namespace catpaq::test
