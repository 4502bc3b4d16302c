#include "client/fetcher.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <map>
#include <cerrno>
#include <cstring>

#include "base/checksum.h"
#include "base/error.h"
#include "common_codec/archive.h"

namespace catpaq {

// ---------------------------------------------------------------------------------------------
// NodeSource blocking helpers

std::vector<uint8_t> NodeSource::fetch(SourceRequest request) {
    static std::atomic<uint64_t> next_id{uint64_t(1) << 62};
    request.id = next_id++;
    submit(request);
    std::vector<SourceResult> results;
    for (;;) {
        results.clear();
        poll(results, 100);
        for (SourceResult& r : results) {
            if (r.id != request.id) continue;
            if (!r.ok) fail("%s: %s", describe().c_str(), r.error.c_str());
            return std::move(r.bytes);
        }
    }
}

std::vector<uint8_t> NodeSource::fetch_range(uint64_t offset, uint64_t size) {
    SourceRequest r;
    r.kind = SourceRequest::Kind::Range;
    r.offset = offset;
    r.size = size;
    return fetch(r);
}

std::vector<uint8_t> NodeSource::fetch_node(uint64_t key, uint64_t offset, uint64_t size) {
    SourceRequest r;
    r.kind = SourceRequest::Kind::Node;
    r.key = key;
    r.offset = offset;
    r.size = size;
    return fetch(r);
}

// ---------------------------------------------------------------------------------------------
// LocalFileSource

LocalFileSource::LocalFileSource(const std::string& path) : path_(path) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) fail("cannot open '%s': %s", path.c_str(), std::strerror(errno));
    struct stat st;
    if (::fstat(fd_, &st) != 0) {
        int err = errno;
        ::close(fd_);
        fail("cannot stat '%s': %s", path.c_str(), std::strerror(err));
    }
    size_ = uint64_t(st.st_size);
}

LocalFileSource::~LocalFileSource() {
    if (fd_ >= 0) ::close(fd_);
}

void LocalFileSource::submit(const SourceRequest& request) {
    std::lock_guard<std::mutex> lock(mutex_);
    queue_.push_back(request);
    cv_.notify_all();
}

void LocalFileSource::cancel(uint64_t id) {
    std::lock_guard<std::mutex> lock(mutex_);
    queue_.erase(std::remove_if(queue_.begin(), queue_.end(), [&](const SourceRequest& r) { return r.id == id; }),
                 queue_.end());
}

void LocalFileSource::wakeup() {
    std::lock_guard<std::mutex> lock(mutex_);
    woken_ = true;
    cv_.notify_all();
}

size_t LocalFileSource::in_flight() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return queue_.size();
}

void LocalFileSource::poll(std::vector<SourceResult>& out, int timeout_ms) {
    std::deque<SourceRequest> work;
    {
        std::unique_lock<std::mutex> lock(mutex_);
        if (queue_.empty() && timeout_ms > 0)
            cv_.wait_for(lock, std::chrono::milliseconds(timeout_ms), [&] { return !queue_.empty() || woken_; });
        woken_ = false;
        work.swap(queue_);
    }
    for (const SourceRequest& req : work) {
        SourceResult r;
        r.id = req.id;
        uint64_t offset = req.offset, size = req.size;
        if (req.kind == SourceRequest::Kind::Prefix) {
            offset = 0;
            size = std::min(req.size, size_);
        }
        if (offset > size_ || size > size_ - offset) {
            r.retryable = false;
            r.error = strprintf("bytes %llu..%llu are outside the file (%llu bytes)", (unsigned long long)offset,
                                (unsigned long long)(offset + size), (unsigned long long)size_);
            out.push_back(std::move(r));
            continue;
        }
        r.bytes.resize(size);
        uint64_t done = 0;
        while (done < size) {
            ssize_t n = ::pread(fd_, r.bytes.data() + done, size - done, off_t(offset + done));
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) {
                r.error = n < 0 ? std::string(std::strerror(errno)) : std::string("unexpected end of file");
                break;
            }
            done += uint64_t(n);
        }
        if (done == size) r.ok = true;
        else r.bytes.clear();
        out.push_back(std::move(r));
    }
}

// ---------------------------------------------------------------------------------------------
// Prefix

std::unique_ptr<NodeSource> open_node_source(const std::string& location, HttpSettings http) {
    if (location.rfind("http://", 0) == 0 || location.rfind("https://", 0) == 0)
        return std::make_unique<HttpSource>(location, http);
    return std::make_unique<LocalFileSource>(location);
}

std::vector<uint8_t> fetch_prefix(NodeSource& source, int attempts) {
    std::string last;
    for (int attempt = 0; attempt < std::max(1, attempts); ++attempt) {
        if (attempt > 0) std::this_thread::sleep_for(std::chrono::milliseconds(100 << std::min(attempt - 1, 4)));
        try {
            SourceRequest probe;
            probe.kind = SourceRequest::Kind::Prefix;
            probe.size = kPrefixProbeBytes;
            std::vector<uint8_t> bytes = source.fetch(probe);
            ArchiveHeader header;
            std::string problem = parse_archive_header(bytes.data(), bytes.size(), header);
            if (!problem.empty()) fail("%s", problem.c_str());
            uint64_t prefix = header.index_offset + header.index_size;
            if (prefix > header.file_size) fail("the index lies past the end of the file");
            // A local file's size is known: a truncated dataset is refused here, not node by node.
            if (auto* local = dynamic_cast<LocalFileSource*>(&source); local && local->file_size() != header.file_size)
                fail("the file is %llu bytes but its header says %llu (truncated or appended to)",
                     (unsigned long long)local->file_size(), (unsigned long long)header.file_size);
            if (bytes.size() < prefix) {
                std::vector<uint8_t> rest = source.fetch_range(bytes.size(), prefix - bytes.size());
                bytes.insert(bytes.end(), rest.begin(), rest.end());
            }
            return bytes;
        } catch (const Error& e) {
            last = e.what();
        }
    }
    fail("%s: cannot load the dataset prefix: %s", source.describe().c_str(), last.c_str());
}

DatasetPrefix load_prefix(NodeSource& source, int attempts) {
    std::vector<uint8_t> bytes = fetch_prefix(source, attempts);
    return DatasetPrefix::parse(bytes.data(), bytes.size(), source.describe());
}

NodeDecoder format_decoder(const DatasetFormat& format) {
    return [&format](const FetchRequest& request, const uint8_t* data, size_t size, std::shared_ptr<const DecodedNode>& out) {
        if (request.part != kWholeNode) return format.decode_part(request.node, request.part, data, size, out);
        if (request.decode_parent) return format.decode_with_parent(request.node, *request.decode_parent, data, size, out);
        return format.decode(request.node, data, size, out);
    };
}

// ---------------------------------------------------------------------------------------------
// Fetcher

FetchRequest FetchRequest::of(const HierarchyNode& node) {
    FetchRequest r;
    r.node = node.index;
    r.key = node.key;
    r.offset = node.payload_offset;
    r.size = node.payload_bytes;
    r.checksum = node.checksum;
    r.id = node.key;
    return r;
}

FetchRequest FetchRequest::of_part(const HierarchyNode& node, size_t part) {
    FetchRequest r;
    r.node = node.index;
    r.key = node.key;
    r.part = uint8_t(part);
    r.id = part_fetch_id(node.index, part);
    r.offset = node.parts[part].offset;
    r.size = node.parts[part].size;
    return r;
}

Fetcher::Fetcher(std::unique_ptr<NodeSource> source, FetcherSettings settings)
    : source_(std::move(source)), settings_(std::move(settings)) {
    if (settings_.max_attempts == 0) settings_.max_attempts = 1;
    size_t threads = std::max<size_t>(1, settings_.decode_threads);
    for (size_t i = 0; i < threads; ++i) workers_.emplace_back([this] { decode_loop(); });
    fetch_thread_ = std::thread([this] { fetch_loop(); });
}

Fetcher::~Fetcher() {
    stop_ = true;
    source_->wakeup();
    {
        std::lock_guard<std::mutex> lock(decode_mutex_);
        decode_cv_.notify_all();
    }
    if (fetch_thread_.joinable()) fetch_thread_.join();
    for (std::thread& t : workers_) t.join();
}

void Fetcher::request(const std::vector<FetchRequest>& wanted) {
    {
        std::lock_guard<std::mutex> lock(command_mutex_);
        wanted_ = wanted;
        has_wanted_ = true;
        wanted_seq_ = ++command_seq_;
    }
    source_->wakeup();
}

void Fetcher::cancel(const std::vector<uint64_t>& keys) {
    if (keys.empty()) return;
    {
        std::lock_guard<std::mutex> lock(command_mutex_);
        cancels_.insert(cancels_.end(), keys.begin(), keys.end());
        command_seq_++;
    }
    source_->wakeup();
}

void Fetcher::supply(const FetchRequest& request, std::shared_ptr<const std::vector<uint8_t>> bytes) {
    {
        std::lock_guard<std::mutex> lock(command_mutex_);
        DecodeJob job;
        job.request = request;
        job.bytes = std::move(bytes);
        job.supplied = true;
        supplied_.push_back(std::move(job));
        command_seq_++;
    }
    source_->wakeup();
}

size_t Fetcher::poll(std::vector<FetchedNode>& out) {
    uint64_t seq;
    {
        std::lock_guard<std::mutex> lock(command_mutex_);
        seq = command_seq_;
    }
    std::deque<FetchedNode> done;
    {
        std::lock_guard<std::mutex> lock(done_mutex_);
        done.swap(done_);
        // Lists issued up to now may still name these nodes: they must not fetch them again.
        for (const FetchedNode& n : done)
            if (n.ok) recent_[n.id] = seq;
    }
    for (FetchedNode& n : done) out.push_back(std::move(n));
    return done.size();
}

FetcherStats Fetcher::stats() const {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    return stats_;
}

bool Fetcher::idle() const {
    uint64_t seq;
    {
        std::lock_guard<std::mutex> lock(command_mutex_);
        seq = command_seq_;
    }
    std::lock_guard<std::mutex> lock(stats_mutex_);
    return applied_seq_ == seq && !stats_.queued && !stats_.in_flight && !stats_.decoding && !stats_.waiting_retry;
}

void Fetcher::deliver(FetchedNode node) {
    std::lock_guard<std::mutex> lock(done_mutex_);
    if (node.ok) recent_[node.id] = kUnpolled;
    done_.push_back(std::move(node));
}

void Fetcher::fetch_loop() {
    while (!stop_) {
        try {
            fetch_iterations();
        } catch (const std::exception&) {
            // Nothing a source or a decoder throws may end the fetch thread (the render thread
            // would wait forever): drop what was running and start over after a pause.
            for (auto& [key, e] : entries_)
                if (e.state == State::Running) e.state = State::Queued;
            transfer_key_.clear();
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
    }
}

void Fetcher::fetch_iterations() {
    std::vector<SourceResult> results;
    std::deque<DecodeDone> decoded;
    while (!stop_) {
        uint64_t seq = apply_commands();
        auto now = std::chrono::steady_clock::now();
        for (auto& [key, e] : entries_) {
            if (e.state == State::Backoff && e.retry_at <= now) e.state = State::Queued;
            if (e.state == State::Failed && e.wanted && e.retry_at <= now) {
                e.state = State::Queued;
                e.attempts = 0;
            }
        }
        {
            std::lock_guard<std::mutex> lock(decode_mutex_);
            decoded.swap(decoded_);
        }
        for (DecodeDone& d : decoded) handle_decoded(d);
        decoded.clear();
        dispatch();
        update_counts(seq);

        // Wait for transfers, commands (wakeup) or the next retry, whichever comes first.
        auto wait = std::chrono::milliseconds(50);
        now = std::chrono::steady_clock::now();
        for (const auto& [key, e] : entries_)
            if (e.state == State::Backoff || (e.state == State::Failed && e.wanted))
                wait = std::min(wait, std::chrono::duration_cast<std::chrono::milliseconds>(
                                          std::max(e.retry_at - now, std::chrono::steady_clock::duration::zero())));
        results.clear();
        source_->poll(results, int(wait.count()));
        for (SourceResult& r : results) handle_result(r);
        update_counts(seq);
    }
}

uint64_t Fetcher::apply_commands() {
    bool has_wanted;
    std::vector<FetchRequest> wanted;
    std::vector<uint64_t> cancels;
    std::vector<DecodeJob> supplied;
    uint64_t seq, wanted_seq;
    {
        std::lock_guard<std::mutex> lock(command_mutex_);
        has_wanted = has_wanted_;
        wanted_seq = wanted_seq_;
        has_wanted_ = false;
        wanted.swap(wanted_);
        cancels.swap(cancels_);
        supplied.swap(supplied_);
        seq = command_seq_;
    }
    auto now = std::chrono::steady_clock::now();
    // Forgets a node nobody wants any more; a running transfer finishes (its bytes are still
    // useful to a cache) unless abort_stale_in_flight.
    auto drop = [&](std::unordered_map<uint64_t, Entry>::iterator it) {
        Entry& e = it->second;
        switch (e.state) {
            case State::Queued:
            case State::Backoff:
                stats_cancelled_++;
                entries_.erase(it);
                return;
            case State::Failed:
                entries_.erase(it);
                return;
            case State::Running:
                // A transfer that carries other fetches too runs on.
                if (settings_.abort_stale_in_flight && transfer_key_.count(e.transfer) &&
                    transfer_key_[e.transfer].ids.size() == 1) {
                    source_->cancel(e.transfer);
                    transfer_key_.erase(e.transfer);
                    stats_cancelled_++;
                    entries_.erase(it);
                } else {
                    e.stale = true;
                    e.wanted = false;
                }
                return;
            case State::Decoding:
                e.stale = true;
                e.wanted = false;
                return;
        }
    };
    if (has_wanted) {
        // A node delivered and not polled yet, or polled after this list was issued, is in the
        // list only because the caller did not know yet: do not fetch it again.
        std::unordered_map<uint64_t, uint64_t> recent;
        {
            std::lock_guard<std::mutex> lock(done_mutex_);
            for (auto it = recent_.begin(); it != recent_.end();) {
                if (it->second < wanted_seq) it = recent_.erase(it);  // later lists know
                else ++it;
            }
            recent = recent_;
        }
        for (auto& [key, e] : entries_) e.wanted = false;
        order_.clear();
        for (const FetchRequest& req : wanted) {
            if (recent.count(req.id)) continue;
            auto it = entries_.find(req.id);
            if (it == entries_.end()) {
                Entry e;
                e.request = req;
                e.state = State::Queued;
                it = entries_.emplace(req.id, std::move(e)).first;
            } else if (it->second.wanted) {
                continue;  // listed twice
            }
            Entry& e = it->second;
            e.wanted = true;
            e.stale = false;
            if (e.state == State::Failed && e.retry_at <= now) {
                e.state = State::Queued;
                e.attempts = 0;
            }
            order_.push_back(req.id);
        }
        for (auto it = entries_.begin(); it != entries_.end();) {
            auto next = std::next(it);
            if (!it->second.wanted) drop(it);
            it = next;
        }
    }
    for (uint64_t key : cancels) {
        auto it = entries_.find(key);
        if (it == entries_.end()) continue;
        it->second.wanted = false;
        drop(it);
    }
    for (DecodeJob& job : supplied) {
        auto it = entries_.find(job.request.id);
        if (it != entries_.end() && (it->second.state == State::Running || it->second.state == State::Decoding)) continue;
        if (it == entries_.end()) {
            Entry e;
            e.request = job.request;
            e.wanted = false;  // not in the list: delivered, and forgotten if it has to be fetched
            it = entries_.emplace(job.request.id, std::move(e)).first;
        }
        it->second.state = State::Decoding;
        job.attempts = it->second.attempts;
        std::lock_guard<std::mutex> lock(decode_mutex_);
        decode_queue_.push_back(std::move(job));
        decode_cv_.notify_one();
    }
    return seq;
}

// Queued fetches that may share a transfer, by (file offset, id): the entries of one kind
// (parts, or whole nodes; the two are never mixed: a part lies inside its node's range).
Fetcher::CoalesceMap Fetcher::coalescable(bool parts) {
    CoalesceMap out;
    if (settings_.coalesce_gap_bytes < 0) return out;
    for (auto& [id, e] : entries_)
        if (e.state == State::Queued && !e.alone && e.request.size > 0 && (e.request.part != kWholeNode) == parts)
            out.emplace(std::make_pair(e.request.offset, id), &e);
    return out;
}

// The fetches `head` carries in its transfer: itself and its neighbours in the file that are
// still queued (in `queued`), each starting within coalesce_gap_bytes of the previous one's end,
// up to max_coalesced_bytes from the first byte to the last. Neighbours after it are taken
// first, so the cap keeps the head near the start of the body. Ids in file order; `end` is
// where the transfer's bytes end.
Fetcher::Transfer Fetcher::gather(uint64_t head_id, const Entry& head, const CoalesceMap& queued, uint64_t& end) const {
    Transfer t;
    t.ids.push_back(head_id);
    t.offset = head.request.offset;
    end = head.request.offset + head.request.size;
    auto at = queued.find(std::make_pair(head.request.offset, head_id));
    if (at == queued.end()) return t;  // not coalescable (retried alone, empty, coalescing off)
    const uint64_t gap = uint64_t(settings_.coalesce_gap_bytes);
    const uint64_t cap = std::max<uint64_t>(settings_.max_coalesced_bytes, end - t.offset);
    for (auto next = std::next(at); next != queued.end(); ++next) {
        const Entry* n = next->second;
        const uint64_t offset = n->request.offset;
        if (n->state != State::Queued || offset < end || offset - end > gap || offset + n->request.size - t.offset > cap)
            break;
        t.ids.push_back(next->first.second);
        end = offset + n->request.size;
    }
    while (at != queued.begin()) {
        auto prev = std::prev(at);
        const Entry* p = prev->second;
        const uint64_t p_end = p->request.offset + p->request.size;
        if (p->state != State::Queued || p_end > t.offset || t.offset - p_end > gap || end - p->request.offset > cap) break;
        t.ids.insert(t.ids.begin(), prev->first.second);
        t.offset = p->request.offset;
        at = prev;
    }
    return t;
}

void Fetcher::dispatch() {
    size_t cap = source_->max_parallel();
    if (source_->in_flight() >= cap) return;
    // Built once per dispatch: the fetches queued now are the ones that may share transfers.
    const CoalesceMap parts = coalescable(true), wholes = coalescable(false);
    for (uint64_t key : order_) {
        if (source_->in_flight() >= cap) break;
        auto it = entries_.find(key);
        if (it == entries_.end() || it->second.state != State::Queued) continue;
        Entry& e = it->second;
        uint64_t end = 0;
        Transfer t = gather(key, e, e.request.part == kWholeNode ? wholes : parts, end);
        SourceRequest sr;
        sr.id = next_transfer_++;
        // One whole node goes by key (the server's node route checks its checksum too); a part or
        // several fetches are a plain byte range (in server mode the raw file route).
        sr.kind = e.request.part == kWholeNode && t.ids.size() == 1 ? SourceRequest::Kind::Node : SourceRequest::Kind::Range;
        sr.key = e.request.key;
        sr.offset = t.offset;
        sr.size = end - t.offset;
        for (uint64_t id : t.ids) {
            Entry& x = entries_.at(id);
            x.state = State::Running;
            x.transfer = sr.id;
            if (x.attempts > 0) stats_retries_++;
        }
        transfer_key_[sr.id] = std::move(t);
        stats_transfers_++;
        source_->submit(sr);
    }
}

void Fetcher::fail_attempt(uint64_t key, const std::string& error, bool permanent) {
    auto it = entries_.find(key);
    if (it == entries_.end()) return;
    Entry& e = it->second;
    e.attempts = permanent ? std::max(e.attempts + 1, settings_.max_attempts) : e.attempts + 1;
    e.last_error = error;
    // Retried in a transfer of its own: a neighbour that shared its failed transfer (or whose
    // bytes are bad) must not fail again with it, nor keep failing the others.
    e.alone = true;
    if (e.stale || !e.wanted) {
        entries_.erase(it);  // nobody is waiting for it
        return;
    }
    auto now = std::chrono::steady_clock::now();
    if (e.attempts >= settings_.max_attempts) {
        e.state = State::Failed;
        e.retry_at = now + settings_.failed_retry_delay;
        stats_failed_++;
        FetchedNode node;
        node.node = e.request.node;
        node.key = e.request.key;
        node.part = e.request.part;
        node.id = key;
        node.ok = false;
        node.error = error;
        node.attempts = e.attempts;
        deliver(std::move(node));
        return;
    }
    auto delay = settings_.backoff_initial * (int64_t(1) << std::min<uint32_t>(e.attempts - 1, 20));
    e.state = State::Backoff;
    e.retry_at = now + std::min<std::chrono::milliseconds>(delay, settings_.backoff_max);
}

void Fetcher::handle_result(SourceResult& r) {
    auto tk = transfer_key_.find(r.id);
    if (tk == transfer_key_.end()) return;  // cancelled
    const Transfer t = std::move(tk->second);
    transfer_key_.erase(tk);
    if (r.ok) stats_bytes_ += r.bytes.size();
    else stats_transport_errors_++;  // one failed transfer, however many fetches it carried
    // A failed transfer of several fetches says nothing final about any one of them (a 416 or an
    // ignored range may be due to one node's range): each is retried alone, never given up here.
    const bool permanent = !r.ok && !r.retryable && t.ids.size() == 1;
    auto bytes = std::make_shared<const std::vector<uint8_t>>(std::move(r.bytes));
    for (uint64_t key : t.ids) {
        auto it = entries_.find(key);
        if (it == entries_.end() || it->second.state != State::Running || it->second.transfer != r.id) continue;
        Entry& e = it->second;
        if (!r.ok) {
            fail_attempt(key, r.error, permanent);
            continue;
        }
        e.state = State::Decoding;
        DecodeJob job;
        job.request = e.request;
        if (t.ids.size() == 1) {
            job.bytes = bytes;
        } else {
            // This fetch's slice of the coalesced range (a short body gives a short slice: the
            // size check on the workers reports it).
            const uint64_t from = std::min<uint64_t>(e.request.offset - t.offset, bytes->size());
            const uint64_t to = std::min<uint64_t>(from + e.request.size, bytes->size());
            job.bytes = std::make_shared<const std::vector<uint8_t>>(bytes->begin() + from, bytes->begin() + to);
        }
        job.attempts = e.attempts + 1;
        std::lock_guard<std::mutex> lock(decode_mutex_);
        decode_queue_.push_back(std::move(job));
        decode_cv_.notify_one();
    }
}

void Fetcher::handle_decoded(DecodeDone& d) {
    auto it = entries_.find(d.node.id);
    if (d.checksum_failed) stats_checksum_failures_++;
    else if (d.corrupt) stats_decode_failures_++;
    if (d.corrupt) {
        if (it != entries_.end() && it->second.state == State::Decoding) {
            if (d.supplied && it->second.wanted) {
                it->second.state = State::Queued;  // the cached bytes were bad: fetch them
            } else {
                fail_attempt(d.node.id, d.node.error, false);
            }
        }
        return;
    }
    if (it != entries_.end() && it->second.state == State::Decoding) entries_.erase(it);
    if (d.supplied) stats_supplied_++;
    stats_delivered_++;
    deliver(std::move(d.node));
}

void Fetcher::decode_loop() {
    for (;;) {
        DecodeJob job;
        {
            std::unique_lock<std::mutex> lock(decode_mutex_);
            decode_cv_.wait(lock, [&] { return stop_ || !decode_queue_.empty(); });
            if (stop_) return;
            job = std::move(decode_queue_.front());
            decode_queue_.pop_front();
        }
        DecodeDone d;
        d.supplied = job.supplied;
        d.node.node = job.request.node;
        d.node.key = job.request.key;
        d.node.part = job.request.part;
        d.node.id = job.request.id;
        d.node.attempts = job.attempts;
        const std::vector<uint8_t>& bytes = *job.bytes;
        const bool whole = job.request.part == kWholeNode;
        if (bytes.size() != job.request.size || (whole && !archive_checksum_matches(job.request.checksum, bytes.data(), bytes.size()))) {
            d.corrupt = true;
            d.checksum_failed = true;
            d.node.error = whole ? strprintf("node %llu: %zu bytes that do not match the index checksum",
                                             (unsigned long long)job.request.key, bytes.size())
                                 : strprintf("node %llu: %zu bytes for a part of %u", (unsigned long long)job.request.key,
                                             bytes.size(), job.request.size);
        } else {
            std::shared_ptr<const DecodedNode> decoded;
            std::string problem;
            if (settings_.decode) {
                try {
                    problem = settings_.decode(job.request, bytes.data(), bytes.size(), decoded);
                } catch (const std::exception& e) {
                    problem = e.what();
                }
                if (problem.empty() && !decoded) problem = "the decoder gave no data";
            }
            if (!problem.empty()) {
                d.corrupt = true;
                d.node.error = strprintf("node %llu: %s", (unsigned long long)job.request.key, problem.c_str());
            } else {
                d.node.ok = true;
                d.node.compressed = job.bytes;
                d.node.decoded = std::move(decoded);
            }
        }
        {
            std::lock_guard<std::mutex> lock(decode_mutex_);
            decoded_.push_back(std::move(d));
        }
        source_->wakeup();
    }
}

void Fetcher::update_counts(uint64_t seq) {
    size_t queued = 0, running = 0, decoding = 0, waiting = 0;
    for (const auto& [key, e] : entries_) {
        switch (e.state) {
            case State::Queued: queued++; break;
            case State::Running: running++; break;
            case State::Decoding: decoding++; break;
            case State::Backoff: waiting++; break;
            case State::Failed: break;
        }
    }
    std::lock_guard<std::mutex> lock(stats_mutex_);
    stats_.transfers = stats_transfers_;
    stats_.bytes_fetched = stats_bytes_;
    stats_.delivered = stats_delivered_;
    stats_.transport_errors = stats_transport_errors_;
    stats_.checksum_failures = stats_checksum_failures_;
    stats_.decode_failures = stats_decode_failures_;
    stats_.retries = stats_retries_;
    stats_.failed = stats_failed_;
    stats_.cancelled = stats_cancelled_;
    stats_.supplied = stats_supplied_;
    stats_.queued = queued;
    stats_.in_flight = running;
    stats_.decoding = decoding;
    stats_.waiting_retry = waiting;
    applied_seq_ = seq;
}

}  // namespace catpaq
