// The transport of `catpaq serve`: Boost.Asio over epoll, one io_context per I/O thread, a
// hand-written HTTP/1.1 connection loop (parser in http.cpp, answers in router.cpp).
//
// Why not cpp-httplib: measured with bench/server/run.sh on the 2-core machine (wrk, 100
// keep-alive connections, random 4-40 KB nodes; `catpaq serve` vs nginx serving the same file by
// Range requests), a cpp-httplib server doing the same node route as well as its API allows
// (pre-routing handler instead of std::regex routes, a content provider sending from the memory
// mapping, a 108-thread pool because every keep-alive connection pins a pool thread) reached
// 0.49x-0.70x of nginx's requests/s with p99 latencies up to 1.4 s and occasional timeouts: it
// makes about 10 system calls per keep-alive request (5 polls, recv, getpeername, getsockname,
// separate sends for headers and body), context-switches between ~100 blocked threads, and its
// thread-per-connection model needs a thread per idle keep-alive client.
// This event loop reads once, parses every pipelined request in the buffer and answers them with
// one gather write straight from the dataset's memory mapping (about 2 system calls per request):
// 0.93x-2.04x of nginx's requests/s in the same runs, comparable p99, no errors
// (bench/server/README.md).
//
// Per connection: read -> parse all complete requests -> queue responses -> gather-write ->
// repeat. Bodies of requests are read and discarded. A sweeper timer per thread enforces the
// timeout: a request must be complete within `timeout` of the connection going idle (slow-loris
// clients get 408 and are closed), and each write must make progress within `timeout`. After a
// response that closes the connection, the send side is shut down and input is drained for a
// moment ("lingering close") so the client reads the response instead of a reset.
#include "server/server.h"

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <pthread.h>
#include <sys/socket.h>
#include <thread>
#include <unordered_set>

#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>

#include "base/error.h"
#include "datasets.h"
#include "http.h"
#include "log.h"
#include "router.h"

namespace catpaq {

namespace asio = boost::asio;
using tcp = asio::ip::tcp;
using Clock = std::chrono::steady_clock;
using boost::system::error_code;

namespace serve {
namespace {

constexpr size_t kInitialBuffer = 4096;
constexpr size_t kMaxQueuedResponses = 32;             // per write batch (pipelining)
constexpr size_t kMaxQueuedBytes = size_t(4) << 20;    // per write batch
constexpr size_t kMaxIovecs = 64;

class Connection;

// Immutable after start, shared by all I/O threads.
struct Shared {
    explicit Shared(ServerSettings s)
        : settings(std::move(s)), log(settings.log_level, settings.log), router(registry, stats, log) {}
    ServerSettings settings;
    Logger log;
    Registry registry;
    ServerStats stats;
    http::Limits limits;
    Router router;
    Clock::duration timeout{};
};

struct Worker {
    explicit Worker(WorkerStats* stats) : io(1), sweeper(io) { context.stats = stats; }
    asio::io_context io;
    asio::steady_timer sweeper;
    std::unordered_set<Connection*> connections;
    WorkerContext context;
    bool stopping = false;
    std::thread thread;
};

class Connection : public std::enable_shared_from_this<Connection> {
public:
    Connection(Shared& shared, Worker& worker, tcp::socket socket)
        : shared_(shared), worker_(worker), socket_(std::move(socket)),
          buffer_(new char[kInitialBuffer]), capacity_(kInitialBuffer),
          max_capacity_(http::max_request_head(shared.limits) + 1) {}

    ~Connection() {
        worker_.connections.erase(this);
        shared_.stats.open_connections.fetch_sub(1, std::memory_order_relaxed);
        if (worker_.stopping && worker_.connections.empty()) worker_.sweeper.cancel();
    }

    void start() {
        worker_.connections.insert(this);
        error_code ec;
        socket_.set_option(tcp::no_delay(true), ec);
        deadline_ = Clock::now() + shared_.timeout;
        read();
    }

    // Server shutdown: idle connections close now; a batch being written finishes first.
    void stop() {
        if (state_ == State::Reading) close();
    }

    void sweep(Clock::time_point now) {
        if (state_ == State::Closed || now < deadline_) return;
        shared_.stats.timeouts.fetch_add(1, std::memory_order_relaxed);
        if (state_ == State::Reading && (in_end_ > in_begin_ || discard_ > 0)) {
            // A request started but did not arrive in time: say so, best effort, then close.
            Response r;
            shared_.router.reject(408, "request not received within the timeout", worker_.context, r);
            std::string bytes = r.head + r.owned;
            ssize_t sent = ::send(socket_.native_handle(), bytes.data(), bytes.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
            (void)sent;
            log_response(r, Clock::now());
        }
        shared_.log.logf(LogLevel::Debug, "closing a connection: timeout while %s",
                         state_ == State::Reading ? "reading" : state_ == State::Writing ? "writing" : "closing");
        close();
    }

private:
    enum class State { Reading, Writing, Lingering, Closed };

    void read() {
        if (in_begin_ == in_end_) {
            in_begin_ = in_end_ = 0;
            if (discard_ == 0) deadline_ = Clock::now() + shared_.timeout;  // idle: a new request may start
        } else if (in_end_ == capacity_) {
            if (in_begin_ > 0) {
                std::memmove(buffer_.get(), buffer_.get() + in_begin_, in_end_ - in_begin_);
                in_end_ -= in_begin_;
                in_begin_ = 0;
            } else if (capacity_ < max_capacity_) {
                size_t capacity = std::min(capacity_ * 4, max_capacity_);
                std::unique_ptr<char[]> grown(new char[capacity]);
                std::memcpy(grown.get(), buffer_.get(), in_end_);
                buffer_ = std::move(grown);
                capacity_ = capacity;
            } else {
                close();  // cannot happen: the parser rejects heads before the buffer is full
                return;
            }
        }
        state_ = State::Reading;
        socket_.async_read_some(asio::buffer(buffer_.get() + in_end_, capacity_ - in_end_),
                                [self = shared_from_this()](const error_code& ec, size_t n) { self->on_read(ec, n); });
    }

    void on_read(const error_code& ec, size_t n) {
        if (ec || state_ == State::Closed) return close();
        in_end_ += n;
        process();
    }

    Response& next_response() {
        if (queued_ == out_.size()) out_.emplace_back();
        Response& r = out_[queued_++];
        r.reset();
        if (shared_.log.enabled(LogLevel::Info)) r.started = Clock::now();
        return r;
    }

    void process() {
        WorkerContext& context = worker_.context;
        context.refresh_date();
        const bool log_requests = shared_.log.enabled(LogLevel::Info);
        size_t queued_bytes = 0;
        while (queued_ < kMaxQueuedResponses && queued_bytes < kMaxQueuedBytes) {
            if (discard_ > 0) {  // the body of the previous request
                size_t n = std::min<uint64_t>(discard_, in_end_ - in_begin_);
                in_begin_ += n;
                discard_ -= n;
                if (discard_ > 0) break;
            }
            if (scanned_ == 0)  // tolerate empty lines between requests (RFC 9112 section 2.2)
                while (in_begin_ < in_end_ && (buffer_[in_begin_] == '\r' || buffer_[in_begin_] == '\n')) ++in_begin_;
            if (in_begin_ == in_end_) break;

            http::Request request;
            http::ParseError problem;
            http::ParseResult result = http::parse_request(buffer_.get() + in_begin_, in_end_ - in_begin_,
                                                           shared_.limits, request, problem, scanned_);
            if (result == http::ParseResult::Incomplete) break;
            Response& r = next_response();
            if (result == http::ParseResult::Error) {
                if (log_requests) {
                    std::string_view raw(buffer_.get() + in_begin_, std::min<size_t>(in_end_ - in_begin_, 80));
                    r.log_request = "- " + http::printable(raw.substr(0, raw.find('\n')), 80);
                }
                shared_.router.reject(problem.status, problem.message, context, r);
                in_begin_ = in_end_;
                break;
            }
            in_begin_ += request.head_size;
            if (log_requests)
                r.log_request = std::string(request.method) + " " + http::printable(request.target);
            const bool close = !request.keep_alive || worker_.stopping;
            if (request.has_transfer_encoding) {
                shared_.router.reject(501, "request bodies with Transfer-Encoding are not supported", context, r);
            } else if (request.content_length > shared_.settings.max_body_bytes) {
                shared_.router.reject(413, "request body too large", context, r);
            } else {
                discard_ = request.content_length;
                shared_.router.handle(request, close, context, r);
            }
            queued_bytes += r.wire_size();
            if (r.close) {
                in_begin_ = in_end_;
                discard_ = 0;
                break;
            }
        }
        if (queued_ > 0) {
            write();
        } else {
            read();
        }
    }

    void write() {
        iov_.clear();
        size_t offset = write_offset_;
        for (size_t i = write_index_; i < queued_ && iov_.size() + 2 <= kMaxIovecs; ++i) {
            const Response& r = out_[i];
            if (offset < r.head.size()) iov_.emplace_back(r.head.data() + offset, r.head.size() - offset);
            size_t body_from = offset > r.head.size() ? offset - r.head.size() : 0;
            if (!r.head_only && r.body_size > body_from)
                iov_.emplace_back(r.body_data() + body_from, r.body_size - body_from);
            offset = 0;
        }
        state_ = State::Writing;
        socket_.async_write_some(iov_, [self = shared_from_this()](const error_code& ec, size_t n) {
            self->on_write(ec, n);
        });
    }

    void on_write(const error_code& ec, size_t n) {
        worker_.context.stats->bytes_sent.fetch_add(n, std::memory_order_relaxed);
        if (ec || state_ == State::Closed) return close();
        Clock::time_point now = Clock::now();
        deadline_ = now + shared_.timeout;  // progress
        bool close_after = false;
        while (n > 0 && write_index_ < queued_) {
            const Response& r = out_[write_index_];
            size_t remaining = r.wire_size() - write_offset_;
            if (n < remaining) {
                write_offset_ += n;
                break;
            }
            n -= remaining;
            log_response(r, now);
            close_after = close_after || r.close;
            ++write_index_;
            write_offset_ = 0;
        }
        if (write_index_ < queued_ && !close_after) return write();
        queued_ = write_index_ = write_offset_ = 0;
        if (close_after || worker_.stopping) return linger();
        process();
    }

    void log_response(const Response& r, Clock::time_point now) {
        if (!shared_.log.enabled(LogLevel::Info)) return;
        long long us = std::chrono::duration_cast<std::chrono::microseconds>(now - r.started).count();
        if (r.log_note.empty() || r.status < 400)
            shared_.log.logf(LogLevel::Info, "%s %d %zu %lldus", r.log_request.c_str(), r.status, r.wire_size(), us);
        else
            shared_.log.logf(LogLevel::Info, "%s %d %zu %lldus (%s)", r.log_request.c_str(), r.status, r.wire_size(),
                             us, r.log_note.c_str());
    }

    // After a response that closes the connection: stop sending, read and drop what the client
    // still sends until it closes or a short deadline passes, then close.
    void linger() {
        state_ = State::Lingering;
        error_code ec;
        socket_.shutdown(tcp::socket::shutdown_send, ec);
        if (ec) return close();
        deadline_ = Clock::now() + std::min<Clock::duration>(shared_.timeout, std::chrono::seconds(2));
        drain();
    }

    void drain() {
        socket_.async_read_some(asio::buffer(buffer_.get(), capacity_),
                                [self = shared_from_this()](const error_code& ec, size_t) {
                                    if (ec || self->state_ == State::Closed) return self->close();
                                    self->drain();
                                });
    }

    void close() {
        if (state_ == State::Closed) return;
        state_ = State::Closed;
        error_code ec;
        socket_.close(ec);
    }

    Shared& shared_;
    Worker& worker_;
    tcp::socket socket_;
    State state_ = State::Reading;
    Clock::time_point deadline_;

    std::unique_ptr<char[]> buffer_;
    size_t capacity_, max_capacity_;
    size_t in_begin_ = 0, in_end_ = 0, scanned_ = 0;
    uint64_t discard_ = 0;

    std::vector<Response> out_;  // reused across batches (keeps string capacity)
    size_t queued_ = 0, write_index_ = 0, write_offset_ = 0;
    std::vector<asio::const_buffer> iov_;
};

}  // namespace
}  // namespace serve

using namespace serve;

struct StreamingServer::Impl {
    explicit Impl(ServerSettings settings) : shared(std::move(settings)) {}

    void accept() {
        Worker& target = *workers[next_worker];
        next_worker = (next_worker + 1) % workers.size();
        acceptor->async_accept(target.io, [this, &target](const error_code& ec, tcp::socket socket) {
            if (ec == asio::error::operation_aborted || !acceptor->is_open()) return;
            if (ec) {
                // Out of descriptors or a transient network error: back off briefly, keep serving.
                shared.log.logf(LogLevel::Warn, "accept failed: %s", ec.message().c_str());
                accept_retry->expires_after(std::chrono::milliseconds(50));
                accept_retry->async_wait([this](const error_code& e) {
                    if (!e && acceptor->is_open()) accept();
                });
                return;
            }
            if (shared.stats.open_connections.load(std::memory_order_relaxed) >= shared.settings.max_connections) {
                shared.stats.connections_refused.fetch_add(1, std::memory_order_relaxed);
                static const std::string refusal = Router::refusal();
                ssize_t sent = ::send(socket.native_handle(), refusal.data(), refusal.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
                (void)sent;
                error_code ignored;
                socket.shutdown(tcp::socket::shutdown_send, ignored);
                socket.close(ignored);
                shared.log.logf(LogLevel::Warn, "refused a connection: %d connections open (--max-connections)",
                                shared.settings.max_connections);
            } else {
                shared.stats.open_connections.fetch_add(1, std::memory_order_relaxed);
                shared.stats.connections_accepted.fetch_add(1, std::memory_order_relaxed);
                asio::post(target.io, [this, &target, socket = std::move(socket)]() mutable {
                    auto connection = std::make_shared<Connection>(shared, target, std::move(socket));
                    if (target.stopping) return;  // destroyed at once: closes the socket
                    connection->start();
                });
            }
            accept();
        });
    }

    void sweep(Worker& worker) {
        Clock::duration period = std::clamp<Clock::duration>(shared.timeout / 4, std::chrono::milliseconds(10),
                                                             std::chrono::seconds(1));
        worker.sweeper.expires_after(period);
        worker.sweeper.async_wait([this, &worker](const error_code&) {
            if (worker.stopping && worker.connections.empty()) return;
            Clock::time_point now = Clock::now();
            std::vector<Connection*> current(worker.connections.begin(), worker.connections.end());
            for (Connection* c : current) c->sweep(now);
            sweep(worker);
        });
    }

    void run(Worker& worker) {
        for (;;) {
            try {
                worker.io.run();
                return;
            } catch (const std::exception& e) {  // a handler threw (out of memory, ...): log, keep serving
                shared.log.logf(LogLevel::Error, "I/O thread: %s", e.what());
            }
        }
    }

    Shared shared;
    std::vector<std::unique_ptr<Worker>> workers;
    std::unique_ptr<tcp::acceptor> acceptor;
    std::unique_ptr<asio::steady_timer> accept_retry;
    size_t next_worker = 0;
    uint16_t port = 0;
    std::mutex mutex;       // start/stop
    std::mutex join_mutex;  // wait (not under `mutex`: stop() must get through while wait() blocks)
    std::atomic<bool> started{false};
    bool stopped = false, joined = false;
};

StreamingServer::StreamingServer(ServerSettings settings) : impl_(new Impl(std::move(settings))) {}

StreamingServer::~StreamingServer() {
    stop();
    wait();
}

uint16_t StreamingServer::start() {
    Impl& m = *impl_;
    std::lock_guard lock(m.mutex);
    if (m.started) fail("server already started");
    const ServerSettings& s = m.shared.settings;
    if (s.max_connections < 1) fail("--max-connections must be at least 1");
    if (!(s.timeout_seconds > 0)) fail("--timeout must be positive");
    m.shared.limits.max_url = s.max_url_bytes;
    m.shared.limits.max_header = s.max_header_bytes;
    m.shared.timeout = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s.timeout_seconds));

    m.shared.registry.scan(s.root, s.describers, m.shared.log);

    int threads = s.threads > 0 ? s.threads : int(std::max(1u, std::thread::hardware_concurrency()));
    for (int i = 0; i < threads; ++i) {
        m.shared.stats.workers.push_back(std::make_unique<WorkerStats>());
        m.workers.push_back(std::make_unique<Worker>(m.shared.stats.workers.back().get()));
    }

    error_code ec;
    asio::ip::address address = asio::ip::make_address(s.bind == "localhost" ? "127.0.0.1" : s.bind, ec);
    if (ec) fail("invalid --bind address '%s' (give an IPv4 or IPv6 address)", s.bind.c_str());
    tcp::endpoint endpoint(address, s.port);
    m.acceptor = std::make_unique<tcp::acceptor>(m.workers[0]->io);
    m.accept_retry = std::make_unique<asio::steady_timer>(m.workers[0]->io);
    m.acceptor->open(endpoint.protocol(), ec);
    if (!ec) m.acceptor->set_option(tcp::acceptor::reuse_address(true), ec);
    if (!ec) m.acceptor->bind(endpoint, ec);
    if (!ec) m.acceptor->listen(asio::socket_base::max_listen_connections, ec);
    if (ec) fail("cannot listen on %s port %u: %s", s.bind.c_str(), unsigned(s.port), ec.message().c_str());
    m.port = m.acceptor->local_endpoint().port();

    m.shared.stats.started = Clock::now();
    m.accept();
    for (auto& w : m.workers) m.sweep(*w);
    for (auto& w : m.workers) {
        Worker* worker = w.get();
        worker->thread = std::thread([&m, worker] { m.run(*worker); });
    }
    m.started = true;
    return m.port;
}

void StreamingServer::stop() {
    Impl& m = *impl_;
    std::lock_guard lock(m.mutex);
    if (!m.started || m.stopped) return;
    m.stopped = true;
    asio::post(m.workers[0]->io, [&m] {
        error_code ec;
        m.acceptor->close(ec);
        m.accept_retry->cancel();
    });
    for (auto& w : m.workers) {
        Worker* worker = w.get();
        asio::post(worker->io, [worker] {
            worker->stopping = true;
            std::vector<Connection*> current(worker->connections.begin(), worker->connections.end());
            for (Connection* c : current) c->stop();
            if (worker->connections.empty()) worker->sweeper.cancel();
        });
    }
}

void StreamingServer::wait() {
    Impl& m = *impl_;
    std::lock_guard lock(m.join_mutex);
    if (!m.started || m.joined) return;
    for (auto& w : m.workers)
        if (w->thread.joinable()) w->thread.join();
    m.joined = true;
}

uint16_t StreamingServer::port() const { return impl_->port; }

std::vector<std::string> StreamingServer::dataset_names() const {
    std::vector<std::string> names;
    for (const auto& d : impl_->shared.registry.datasets()) names.push_back(d->name);
    return names;
}

int run_server(const ServerSettings& settings) {
    // Block the shutdown signals in every thread (the I/O threads inherit the mask) and take them
    // synchronously here with sigwait: no async-signal-safety concerns.
    sigset_t signals, previous;
    sigemptyset(&signals);
    sigaddset(&signals, SIGINT);
    sigaddset(&signals, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &signals, &previous);
    std::signal(SIGPIPE, SIG_IGN);
    struct Restore {
        sigset_t* mask;
        ~Restore() { pthread_sigmask(SIG_SETMASK, mask, nullptr); }
    } restore{&previous};

    StreamingServer server(settings);
    uint16_t port = server.start();
    bool v6 = settings.bind.find(':') != std::string::npos;
    std::printf("serving %zu datasets on http://%s%s%s:%u/\n", server.dataset_names().size(), v6 ? "[" : "",
                settings.bind.c_str(), v6 ? "]" : "", unsigned(port));
    std::fflush(stdout);
    int signal = 0;
    sigwait(&signals, &signal);
    serve::Logger log(settings.log_level, settings.log);
    log.logf(LogLevel::Info, "%s received: finishing in-flight requests and stopping", strsignal(signal));
    server.stop();
    server.wait();
    log.log(LogLevel::Info, "stopped");
    return 0;
}

}  // namespace catpaq
