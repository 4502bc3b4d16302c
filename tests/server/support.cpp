#include "support.h"

#include <arpa/inet.h>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <random>
#include <stdexcept>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include "catp/format.h"
#include "server_formats/describers.h"

namespace catpaq::test {

namespace fs = std::filesystem;

TempDir::TempDir() {
    std::string pattern = (fs::temp_directory_path() / "catpaq-server-test-XXXXXX").string();
    std::vector<char> buffer(pattern.begin(), pattern.end());
    buffer.push_back(0);
    if (!mkdtemp(buffer.data())) throw std::runtime_error("mkdtemp failed");
    path_ = buffer.data();
}

TempDir::~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
}

std::vector<BuiltNode> write_dataset(const std::string& path, ArchiveKind kind, const std::vector<NodeSpec>& nodes,
                                     uint32_t seed, const double bounds_min[3], const double bounds_max[3]) {
    std::mt19937 rng(seed);
    ArchiveWriter writer(path, kind);
    std::vector<BuiltNode> built;
    for (const NodeSpec& spec : nodes) {
        BuiltNode node;
        node.key = spec.key;
        node.level = spec.level;
        node.bytes.resize(spec.size);
        for (uint8_t& b : node.bytes) b = uint8_t(rng());
        ArchiveEntry entry;
        entry.key = spec.key;
        entry.level = spec.level;
        entry.count = uint32_t(spec.size / 16);
        entry.error = float(100.0 / (1 + spec.level));
        writer.add_node(entry, node.bytes.data(), node.bytes.size());
        built.push_back(std::move(node));
    }
    std::vector<uint8_t> meta;
    if (kind == ArchiveKind::Catp) {
        CatpMeta m;
        for (int i = 0; i < 3; ++i) {
            m.bounds_min[i] = bounds_min ? bounds_min[i] : 0.0;
            m.bounds_max[i] = bounds_max ? bounds_max[i] : 1.0;
            m.origin[i] = m.bounds_min[i];
        }
        m.cell = 1.0 / 1024;
        m.leaf_level = 3;
        m.input_triangles = 1234;
        m.input_vertices = 617;
        meta = encode_catp_meta(m);
    } else {
        meta = {'o', 'p', 'a', 'q', 'u', 'e'};
    }
    writer.finish(meta);
    return built;
}

void flip_byte(const std::string& path, uint64_t offset) {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(std::streamoff(offset));
    char c = 0;
    f.read(&c, 1);
    c = char(c ^ 0x5a);
    f.seekp(std::streamoff(offset));
    f.write(&c, 1);
    if (!f) throw std::runtime_error("flip_byte failed on " + path);
}

std::string read_whole_file(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

void write_text_file(const std::string& path, const std::string& text) {
    std::ofstream f(path, std::ios::binary);
    f << text;
}

Fixture::Fixture() {
    fs::create_directories(root() + "/sub");
    fs::create_directories(outside());
    std::vector<NodeSpec> specs;
    std::mt19937 rng(7);
    for (uint16_t level = 0; level < 4; ++level)
        for (uint64_t i = 0; i < 10; ++i) {
            uint64_t key = (uint64_t(level) << 56) | (i * 3 + 1);
            specs.push_back({key, level, size_t(rng() % 40000)});
        }
    specs.push_back({kEmptyKey, 1, 0});
    specs.push_back({kBigKey, 3, size_t(2) << 20});
    specs.push_back({kHugeKey, 3, 777});
    alpha = write_dataset(root() + "/alpha.cpq", ArchiveKind::Catp, specs, 1, kMin, kMax);

    beta = write_dataset(root() + "/sub/beta.cpq", ArchiveKind::Aqp,
                         {{5, 0, 100}, {6, 1, 2000}, {7, 1, 3000}, {8, 2, 1}, {9, 2, 4096}, {10, 2, 65536}}, 2);
    fs::create_symlink("sub/beta.cpq", root() + "/inside_link.cpq");

    std::vector<NodeSpec> corrupt_specs;
    for (uint64_t i = 0; i < 8; ++i) corrupt_specs.push_back({0x0200000000000000ull | i, 2, 1000 + 100 * i});
    corrupt = write_dataset(root() + "/corrupt_node.cpq", ArchiveKind::Catp, corrupt_specs, 3, kMin, kMax);
    {
        ArchiveReader reader(root() + "/corrupt_node.cpq");
        int64_t index = reader.find(kCorruptKey);
        if (index < 0) throw std::runtime_error("fixture: corrupt key missing");
        uint64_t offset = reader.entries()[size_t(index)].offset + 10;
        flip_byte(root() + "/corrupt_node.cpq", offset);
    }

    write_dataset(root() + "/corrupt_header.cpq", ArchiveKind::Catp, {{1, 0, 100}}, 4, kMin, kMax);
    flip_byte(root() + "/corrupt_header.cpq", 20);

    write_text_file(root() + "/fake.cpq", "this is not a dataset\n");
    write_text_file(root() + "/notes.txt", "notes, not a dataset\n");
    write_dataset(outside() + "/secret.cpq", ArchiveKind::Catp, {{1, 0, 100}}, 5, kMin, kMax);
    write_text_file(outside() + "/secret.txt", "TOP-SECRET\n");
    fs::create_symlink("../outside/secret.cpq", root() + "/escape.cpq");
}

void LogCapture::add(LogLevel level, std::string_view line) {
    std::lock_guard lock(mutex_);
    lines_.push_back(std::string(log_level_name(level)) + " " + std::string(line));
}

std::vector<std::string> LogCapture::lines() const {
    std::lock_guard lock(mutex_);
    return lines_;
}

bool LogCapture::contains(const std::string& a, const std::string& b) const {
    std::lock_guard lock(mutex_);
    for (const std::string& line : lines_)
        if (line.find(a) != std::string::npos && line.find(b) != std::string::npos) return true;
    return false;
}

RunningServer::RunningServer(const std::string& root, ServerSettings settings, bool describe) {
    settings.root = root;
    settings.port = 0;
    if (settings.threads == 0) settings.threads = 2;
    settings.log = [this](LogLevel level, std::string_view line) { log.add(level, line); };
    if (describe && settings.describers.empty()) settings.describers = builtin_dataset_describers();
    server = std::make_unique<StreamingServer>(settings);
    port = server->start();
}

RunningServer::~RunningServer() {
    server->stop();
    server->wait();
}

static std::string lower(std::string s) {
    for (char& c : s)
        if (c >= 'A' && c <= 'Z') c = char(c - 'A' + 'a');
    return s;
}

bool HttpResponse::has(const std::string& name) const {
    for (const auto& [n, v] : headers)
        if (lower(n) == lower(name)) return true;
    return false;
}

std::string HttpResponse::header(const std::string& name) const {
    for (const auto& [n, v] : headers)
        if (lower(n) == lower(name)) return v;
    return "";
}

RawClient::RawClient(uint16_t port, int receive_buffer) {
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    if (fd_ < 0) throw std::runtime_error("socket failed");
    timeval tv{10, 0};  // a hung server fails the test instead of hanging it
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    setsockopt(fd_, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
    if (receive_buffer > 0) setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &receive_buffer, sizeof receive_buffer);
    int one = 1;
    setsockopt(fd_, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(port);
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
        int e = errno;
        ::close(fd_);
        throw std::runtime_error(std::string("connect failed: ") + std::strerror(e));
    }
}

RawClient::~RawClient() {
    if (fd_ >= 0) ::close(fd_);
}

void RawClient::send(const std::string& bytes) {
    size_t sent = 0;
    while (sent < bytes.size()) {
        ssize_t n = ::send(fd_, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
        if (n <= 0) throw std::runtime_error("send failed");
        sent += size_t(n);
    }
}

bool RawClient::fill() {
    char chunk[65536];
    ssize_t n = ::recv(fd_, chunk, sizeof chunk, 0);
    if (n <= 0) return false;
    buffer_.append(chunk, size_t(n));
    return true;
}

bool RawClient::read_raw(size_t n, std::string& out) {
    while (buffer_.size() < n)
        if (!fill()) return false;
    out = buffer_.substr(0, n);
    buffer_.erase(0, n);
    return true;
}

bool RawClient::read(HttpResponse& out, bool head) {
    out = HttpResponse{};
    size_t end;
    while ((end = buffer_.find("\r\n\r\n")) == std::string::npos)
        if (!fill()) return false;
    std::string head_text = buffer_.substr(0, end + 2);
    buffer_.erase(0, end + 4);
    size_t line_end = head_text.find("\r\n");
    std::string status_line = head_text.substr(0, line_end);
    if (status_line.size() < 12) return false;
    out.version = status_line.substr(0, 8);
    out.status = std::atoi(status_line.c_str() + 9);
    size_t pos = line_end + 2;
    while (pos < head_text.size()) {
        size_t eol = head_text.find("\r\n", pos);
        std::string line = head_text.substr(pos, eol - pos);
        pos = eol + 2;
        size_t colon = line.find(':');
        if (colon == std::string::npos) return false;
        std::string value = line.substr(colon + 1);
        while (!value.empty() && value.front() == ' ') value.erase(0, 1);
        out.headers.emplace_back(line.substr(0, colon), value);
    }
    if (head || out.status == 204 || out.status == 304 || out.status / 100 == 1) return true;
    if (out.has("Content-Length")) {
        size_t length = size_t(std::strtoull(out.header("Content-Length").c_str(), nullptr, 10));
        return read_raw(length, out.body);
    }
    while (fill()) {
    }
    out.body = std::move(buffer_);
    buffer_.clear();
    return true;
}

bool RawClient::closed() {
    if (!buffer_.empty()) return false;
    char c;
    ssize_t n = ::recv(fd_, &c, 1, 0);
    if (n == 0) return true;
    if (n < 0) return errno == ECONNRESET;  // a timeout (EAGAIN) means still open
    buffer_.push_back(c);
    return false;
}

HttpResponse RawClient::request(const std::string& method, const std::string& target, const std::string& headers) {
    send(request_text(method, target, headers));
    HttpResponse response;
    if (!read(response, method == "HEAD")) throw std::runtime_error("no response to " + method + " " + target);
    return response;
}

std::string request_text(const std::string& method, const std::string& target, const std::string& headers) {
    return method + " " + target + " HTTP/1.1\r\nHost: localhost\r\n" + headers + "\r\n";
}

std::string to_string(const std::vector<uint8_t>& bytes) { return std::string(bytes.begin(), bytes.end()); }

std::string node_path(const std::string& dataset, uint64_t key) {
    return "/api/datasets/" + dataset + "/nodes/" + std::to_string(key);
}

}  // namespace catpaq::test
