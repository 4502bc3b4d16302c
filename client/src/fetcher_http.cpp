// HttpSource: libcurl's multi interface, persistent HTTP/1.1 connections, parallel transfers.
#include <curl/curl.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <mutex>

#include "base/error.h"
#include "client/fetcher.h"

namespace catpaq {

struct HttpSource::Transfer {
    CURL* easy = nullptr;
    SourceRequest request;
    std::string url;
    std::string range;  // "a-b" or empty
    bool ranged = false;
    uint64_t limit = 0;  // largest body accepted
    std::vector<uint8_t> body;
    bool overflow = false;
    int status = 0;
    std::string content_range;
    char error[CURL_ERROR_SIZE] = {0};
};

namespace {

void global_init() {
    static std::once_flag once;
    std::call_once(once, [] {
        if (curl_global_init(CURL_GLOBAL_DEFAULT) != CURLE_OK) fail("libcurl initialisation failed");
    });
}

size_t write_body(char* data, size_t size, size_t count, void* user) {
    auto* t = static_cast<HttpSource::Transfer*>(user);
    size_t n = size * count;
    if (t->body.size() + n > t->limit) {
        t->overflow = true;
        return 0;  // aborts the transfer (CURLE_WRITE_ERROR)
    }
    t->body.insert(t->body.end(), reinterpret_cast<uint8_t*>(data), reinterpret_cast<uint8_t*>(data) + n);
    return n;
}

bool starts_with_nocase(const std::string& s, const char* prefix) {
    size_t n = std::strlen(prefix);
    if (s.size() < n) return false;
    for (size_t i = 0; i < n; ++i)
        if (std::tolower((unsigned char)s[i]) != std::tolower((unsigned char)prefix[i])) return false;
    return true;
}

std::string trim(std::string s) {
    while (!s.empty() && std::isspace((unsigned char)s.back())) s.pop_back();
    size_t i = 0;
    while (i < s.size() && std::isspace((unsigned char)s[i])) ++i;
    return s.substr(i);
}

size_t read_header(char* data, size_t size, size_t count, void* user) {
    auto* t = static_cast<HttpSource::Transfer*>(user);
    size_t n = size * count;
    std::string line(data, n);
    if (line.rfind("HTTP/", 0) == 0) {
        // A new response (after a redirect or an interim answer): start over.
        size_t sp = line.find(' ');
        t->status = sp == std::string::npos ? 0 : std::atoi(line.c_str() + sp + 1);
        t->content_range.clear();
        t->body.clear();
        t->overflow = false;
    } else if (starts_with_nocase(line, "content-range:")) {
        t->content_range = trim(line.substr(14));
    }
    return n;
}

// "bytes a-b/total" (total may be "*").
bool parse_content_range(const std::string& v, uint64_t& first, uint64_t& last, uint64_t& total, bool& total_known) {
    if (!starts_with_nocase(v, "bytes ")) return false;
    unsigned long long a, b;
    char rest[32] = {0};
    if (std::sscanf(v.c_str() + 6, "%llu-%llu/%31s", &a, &b, rest) != 3 || b < a) return false;
    first = a;
    last = b;
    total_known = rest[0] != '*';
    total = total_known ? std::strtoull(rest, nullptr, 10) : 0;
    return true;
}

bool ends_with(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

bool transient_status(int status) { return status == 0 || status == 408 || status == 429 || status >= 500; }

}  // namespace

HttpSource::HttpSource(const std::string& url, HttpSettings settings) : url_(url), settings_(settings) {
    global_init();
    if (settings_.parallel == 0) settings_.parallel = 1;
    std::string path = url_;
    size_t q = path.find_first_of("?#");
    if (q != std::string::npos) path = path.substr(0, q);
    raw_ = ends_with(path, ".cpq");
    if (!raw_)
        while (!url_.empty() && url_.back() == '/') url_.pop_back();
    CURLM* multi = curl_multi_init();
    if (!multi) fail("libcurl: cannot create a multi handle");
    curl_multi_setopt(multi, CURLMOPT_MAX_HOST_CONNECTIONS, long(settings_.parallel));
    curl_multi_setopt(multi, CURLMOPT_MAX_TOTAL_CONNECTIONS, long(settings_.parallel));
    curl_multi_setopt(multi, CURLMOPT_MAXCONNECTS, long(settings_.parallel));
    curl_multi_setopt(multi, CURLMOPT_PIPELINING, long(CURLPIPE_NOTHING));
    multi_ = multi;
}

HttpSource::~HttpSource() {
    CURLM* multi = static_cast<CURLM*>(multi_);
    for (auto& t : running_) {
        curl_multi_remove_handle(multi, t->easy);
        curl_easy_cleanup(t->easy);
    }
    for (void* e : idle_handles_) curl_easy_cleanup(static_cast<CURL*>(e));
    curl_multi_cleanup(multi);
}

void HttpSource::submit(const SourceRequest& request) {
    pending_.push_back(request);
    start_pending();
}

void HttpSource::cancel(uint64_t id) {
    ready_.erase(std::remove_if(ready_.begin(), ready_.end(), [&](const SourceResult& r) { return r.id == id; }),
                 ready_.end());
    pending_.erase(std::remove_if(pending_.begin(), pending_.end(), [&](const SourceRequest& r) { return r.id == id; }),
                   pending_.end());
    for (size_t i = 0; i < running_.size(); ++i) {
        if (running_[i]->request.id != id) continue;
        curl_multi_remove_handle(static_cast<CURLM*>(multi_), running_[i]->easy);
        idle_handles_.push_back(running_[i]->easy);
        running_.erase(running_.begin() + long(i));
        return;
    }
}

void HttpSource::wakeup() { curl_multi_wakeup(static_cast<CURLM*>(multi_)); }

size_t HttpSource::in_flight() const { return pending_.size() + running_.size() + ready_.size(); }

void HttpSource::start_pending() {
    CURLM* multi = static_cast<CURLM*>(multi_);
    while (!pending_.empty() && running_.size() < settings_.parallel) {
        auto t = std::make_unique<Transfer>();
        t->request = pending_.front();
        pending_.pop_front();
        const SourceRequest& r = t->request;
        uint64_t offset = r.offset, size = r.size;
        if (raw_) {
            t->url = url_;
            t->ranged = true;
        } else if (r.kind == SourceRequest::Kind::Node) {
            t->url = url_ + "/nodes/" + std::to_string(r.key);
        } else if (r.kind == SourceRequest::Kind::Prefix) {
            t->url = url_ + "/prefix";
        } else {
            // A byte range in server mode: the server's raw file route (docs/http-api.md).
            size_t at = url_.find("/api/datasets/");
            if (at == std::string::npos) {
                t->url.clear();
            } else {
                t->url = url_.substr(0, at) + "/files/" + url_.substr(at + 14) + ".cpq";
                t->ranged = true;
            }
        }
        if (r.kind == SourceRequest::Kind::Prefix) offset = 0;
        t->limit = (r.kind == SourceRequest::Kind::Prefix && !raw_) ? (uint64_t(1) << 32) : size;
        bool empty = t->ranged && size == 0;
        if (t->url.empty() || empty) {
            // Nothing to transfer (an empty node), or no way to address a range: answer at once.
            SourceResult res;
            res.id = r.id;
            res.ok = empty;
            res.retryable = false;
            if (!empty) res.error = "byte ranges need a raw .cpq URL or a catpaq server base URL";
            ready_.push_back(std::move(res));
            continue;
        }
        if (t->ranged) t->range = std::to_string(offset) + "-" + std::to_string(offset + size - 1);
        CURL* easy;
        if (!idle_handles_.empty()) {
            easy = static_cast<CURL*>(idle_handles_.back());
            idle_handles_.pop_back();
            curl_easy_reset(easy);
        } else {
            easy = curl_easy_init();
            if (!easy) {
                SourceResult res;
                res.id = r.id;
                res.error = "libcurl: cannot create a transfer";
                ready_.push_back(std::move(res));
                continue;
            }
        }
        t->easy = easy;
        curl_easy_setopt(easy, CURLOPT_URL, t->url.c_str());
        curl_easy_setopt(easy, CURLOPT_HTTP_VERSION, long(CURL_HTTP_VERSION_1_1));
        curl_easy_setopt(easy, CURLOPT_NOSIGNAL, 1L);
        curl_easy_setopt(easy, CURLOPT_TCP_KEEPALIVE, 1L);
        curl_easy_setopt(easy, CURLOPT_TCP_NODELAY, 1L);
        curl_easy_setopt(easy, CURLOPT_CONNECTTIMEOUT_MS, settings_.connect_timeout_ms);
        curl_easy_setopt(easy, CURLOPT_TIMEOUT_MS, settings_.transfer_timeout_ms);
        curl_easy_setopt(easy, CURLOPT_LOW_SPEED_LIMIT, 1L);
        curl_easy_setopt(easy, CURLOPT_LOW_SPEED_TIME, settings_.low_speed_seconds);
        curl_easy_setopt(easy, CURLOPT_FOLLOWLOCATION, 1L);
        curl_easy_setopt(easy, CURLOPT_MAXREDIRS, 4L);
        curl_easy_setopt(easy, CURLOPT_WRITEFUNCTION, write_body);
        curl_easy_setopt(easy, CURLOPT_WRITEDATA, t.get());
        curl_easy_setopt(easy, CURLOPT_HEADERFUNCTION, read_header);
        curl_easy_setopt(easy, CURLOPT_HEADERDATA, t.get());
        curl_easy_setopt(easy, CURLOPT_ERRORBUFFER, t->error);
        curl_easy_setopt(easy, CURLOPT_PRIVATE, t.get());
        if (t->ranged) curl_easy_setopt(easy, CURLOPT_RANGE, t->range.c_str());
        CURLMcode mc = curl_multi_add_handle(multi, easy);
        if (mc != CURLM_OK) {
            SourceResult res;
            res.id = r.id;
            res.error = std::string("libcurl: ") + curl_multi_strerror(mc);
            ready_.push_back(std::move(res));
            idle_handles_.push_back(easy);
            continue;
        }
        running_.push_back(std::move(t));
    }
}

void HttpSource::finish(Transfer* t, int curl_code, std::vector<SourceResult>& out) {
    SourceResult r;
    r.id = t->request.id;
    long status = 0;
    curl_easy_getinfo(t->easy, CURLINFO_RESPONSE_CODE, &status);
    long connects = 0;
    if (curl_easy_getinfo(t->easy, CURLINFO_NUM_CONNECTS, &connects) == CURLE_OK && connects > 0)
        connections_opened_ += uint64_t(connects);
    r.http_status = int(status);
    const SourceRequest& req = t->request;
    std::string where = t->url + (t->ranged ? " [bytes " + t->range + "]" : std::string());
    auto error = [&](bool retryable, const std::string& message) {
        r.ok = false;
        r.retryable = retryable;
        r.error = where + ": " + message;
    };
    if (curl_code != CURLE_OK) {
        if (t->overflow) {
            // More bytes than asked for: a server that ignored the Range header (200 with the
            // whole file), or a node route returning the wrong node.
            error(!t->ranged && transient_status(int(status)),
                  strprintf("HTTP %ld with more than the %llu bytes asked for%s", status, (unsigned long long)t->limit,
                            t->ranged ? " (the server ignored the Range request)" : ""));
        } else {
            error(true, t->error[0] ? std::string(t->error) : std::string(curl_easy_strerror(CURLcode(curl_code))));
        }
    } else if (!t->ranged) {
        // Server routes: 200 with the whole answer.
        if (status != 200) {
            error(transient_status(int(status)), strprintf("HTTP %ld", status));
        } else if (req.kind == SourceRequest::Kind::Node && t->body.size() != req.size) {
            error(true, strprintf("%zu bytes, the index says %llu", t->body.size(), (unsigned long long)req.size));
        } else {
            r.ok = true;
        }
    } else {
        uint64_t offset = req.kind == SourceRequest::Kind::Prefix ? 0 : req.offset;
        uint64_t size = req.size;
        if (status == 206) {
            uint64_t first = 0, last = 0, total = 0;
            bool total_known = false;
            if (!parse_content_range(t->content_range, first, last, total, total_known)) {
                error(true, "206 without a valid Content-Range");
            } else if (first != offset || last - first + 1 != t->body.size()) {
                error(true, strprintf("206 with Content-Range '%s' and %zu bytes for a request at %llu",
                                      t->content_range.c_str(), t->body.size(), (unsigned long long)offset));
            } else if (t->body.size() != size &&
                       !(req.kind == SourceRequest::Kind::Prefix && t->body.size() < size && total_known &&
                         last + 1 == total)) {
                error(true, strprintf("%zu bytes of the %llu asked for", t->body.size(), (unsigned long long)size));
            } else {
                r.ok = true;
            }
        } else if (status == 200) {
            // The whole file: acceptable only when the request covered the whole file (the write
            // limit already refused longer bodies).
            bool whole = offset == 0 && (t->body.size() == size ||
                                         (req.kind == SourceRequest::Kind::Prefix && t->body.size() < size));
            if (whole) r.ok = true;
            else error(false, strprintf("HTTP 200 with %zu bytes instead of a 206 partial answer", t->body.size()));
        } else {
            error(transient_status(int(status)), strprintf("HTTP %ld%s", status, status == 416 ? " (range not satisfiable)" : ""));
        }
    }
    if (r.ok) r.bytes = std::move(t->body);
    out.push_back(std::move(r));
}

void HttpSource::collect(std::vector<SourceResult>& out) {
    CURLM* multi = static_cast<CURLM*>(multi_);
    int left = 0;
    while (CURLMsg* msg = curl_multi_info_read(multi, &left)) {
        if (msg->msg != CURLMSG_DONE) continue;
        CURL* easy = msg->easy_handle;
        CURLcode code = msg->data.result;
        auto it = std::find_if(running_.begin(), running_.end(), [&](const auto& t) { return t->easy == easy; });
        if (it == running_.end()) continue;
        std::unique_ptr<Transfer> t = std::move(*it);
        running_.erase(it);
        finish(t.get(), int(code), out);
        curl_multi_remove_handle(multi, easy);
        idle_handles_.push_back(easy);
    }
}

void HttpSource::poll(std::vector<SourceResult>& out, int timeout_ms) {
    CURLM* multi = static_cast<CURLM*>(multi_);
    size_t before = out.size();
    start_pending();
    for (SourceResult& r : ready_) out.push_back(std::move(r));
    ready_.clear();
    int running = 0;
    curl_multi_perform(multi, &running);
    collect(out);
    if (out.size() == before && timeout_ms > 0) {
        curl_multi_poll(multi, nullptr, 0, timeout_ms, nullptr);
        curl_multi_perform(multi, &running);
        collect(out);
    }
    start_pending();
    for (SourceResult& r : ready_) out.push_back(std::move(r));
    ready_.clear();
}

}  // namespace catpaq
