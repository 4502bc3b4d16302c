#include "http.h"

#include <cstdio>
#include <cstring>
#include <ctime>

namespace catpaq::http {

namespace {

// RFC 9110 token characters.
struct TokenTable {
    bool ok[256] = {};
    TokenTable() {
        for (int c = '0'; c <= '9'; ++c) ok[c] = true;
        for (int c = 'a'; c <= 'z'; ++c) ok[c] = true;
        for (int c = 'A'; c <= 'Z'; ++c) ok[c] = true;
        for (const char* p = "!#$%&'*+-.^_`|~"; *p; ++p) ok[uint8_t(*p)] = true;
    }
};
const TokenTable kToken;

bool is_token(std::string_view s) {
    if (s.empty()) return false;
    for (char c : s)
        if (!kToken.ok[uint8_t(c)]) return false;
    return true;
}

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
    return s;
}

int hex_value(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

bool parse_u64(std::string_view s, uint64_t& out) {
    if (s.empty() || s.size() > 20) return false;
    uint64_t v = 0;
    for (char c : s) {
        if (c < '0' || c > '9') return false;
        uint64_t d = uint64_t(c - '0');
        if (v > (UINT64_MAX - d) / 10) return false;
        v = v * 10 + d;
    }
    out = v;
    return true;
}

// Calls fn(token) for each comma-separated, trimmed, non-empty element of a list header.
template <class Fn>
void for_each_list_element(std::string_view list, Fn fn) {
    while (!list.empty()) {
        size_t comma = list.find(',');
        std::string_view item = trim(list.substr(0, comma));
        if (!item.empty()) fn(item);
        if (comma == std::string_view::npos) break;
        list.remove_prefix(comma + 1);
    }
}

ParseResult fail(ParseError& error, int status, const char* message) {
    error.status = status;
    error.message = message;
    return ParseResult::Error;
}

}  // namespace

bool iequals(std::string_view a, std::string_view b) {
    if (a.size() != b.size()) return false;
    for (size_t i = 0; i < a.size(); ++i) {
        char x = a[i], y = b[i];
        if (x >= 'A' && x <= 'Z') x = char(x - 'A' + 'a');
        if (y >= 'A' && y <= 'Z') y = char(y - 'A' + 'a');
        if (x != y) return false;
    }
    return true;
}

size_t max_request_head(const Limits& limits) {
    // method (<= 32) + SP + target + SP + "HTTP/1.1" + CRLF, then the header section + CRLF.
    return limits.max_url + 64 + limits.max_header + 2;
}

ParseResult parse_request(const char* data, size_t size, const Limits& limits, Request& req, ParseError& error,
                          size_t& scanned) {
    const size_t line_limit = limits.max_url + 64;
    // Find the end of the head: a line feed followed by an empty line (CRLF or bare LF).
    size_t head_end = 0;
    size_t i = scanned;
    while (i < size) {
        const void* nl = std::memchr(data + i, '\n', size - i);
        if (!nl) {
            i = size;
            break;
        }
        size_t k = size_t(static_cast<const char*>(nl) - data);
        if (k + 1 < size && data[k + 1] == '\n') {
            head_end = k + 2;
            break;
        }
        if (k + 2 < size && data[k + 1] == '\r' && data[k + 2] == '\n') {
            head_end = k + 3;
            break;
        }
        if (k + 2 >= size && (k + 1 >= size || data[k + 1] == '\r')) {
            i = k;  // cannot tell yet whether an empty line follows
            break;
        }
        i = k + 1;
    }
    const void* first_nl = std::memchr(data, '\n', size < line_limit + 1 ? size : line_limit + 1);
    if (!head_end) {
        scanned = i;
        if (!first_nl) {
            if (size > line_limit) return fail(error, 414, "request line too long");
        } else {
            size_t line_end = size_t(static_cast<const char*>(first_nl) - data) + 1;
            if (size - line_end > limits.max_header) return fail(error, 431, "request header section too large");
        }
        return ParseResult::Incomplete;
    }
    if (!first_nl) return fail(error, 414, "request line too long");

    req = Request{};
    req.head_size = head_end;
    // Request line: method SP request-target SP HTTP-version.
    size_t line_end = size_t(static_cast<const char*>(first_nl) - data);
    std::string_view line(data, line_end);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    size_t sp1 = line.find(' ');
    size_t sp2 = sp1 == std::string_view::npos ? sp1 : line.find(' ', sp1 + 1);
    if (sp2 == std::string_view::npos || line.find(' ', sp2 + 1) != std::string_view::npos)
        return fail(error, 400, "malformed request line");
    req.method = line.substr(0, sp1);
    req.target = line.substr(sp1 + 1, sp2 - sp1 - 1);
    std::string_view version = line.substr(sp2 + 1);
    if (!is_token(req.method) || req.method.size() > 32) return fail(error, 400, "malformed request method");
    if (req.target.empty()) return fail(error, 400, "empty request target");
    if (req.target.size() > limits.max_url) return fail(error, 414, "request target too long");
    for (char c : req.target)
        if (uint8_t(c) <= 0x20 || uint8_t(c) >= 0x7f) return fail(error, 400, "invalid byte in request target");
    if (version.size() != 8 || version.compare(0, 5, "HTTP/") != 0 || version[6] != '.' || version[5] < '0' ||
        version[5] > '9' || version[7] < '0' || version[7] > '9')
        return fail(error, 400, "malformed HTTP version");
    if (version[5] != '1' || (version[7] != '0' && version[7] != '1'))
        return fail(error, 505, "only HTTP/1.0 and HTTP/1.1 are supported");
    req.version_minor = version[7] - '0';

    // Header fields.
    if (head_end - (line_end + 1) > limits.max_header + 2) return fail(error, 431, "request header section too large");
    bool close = false, keep_alive = false;
    size_t count = 0;
    size_t pos = line_end + 1;
    while (pos < head_end) {
        const char* start = data + pos;
        const char* nl = static_cast<const char*>(std::memchr(start, '\n', head_end - pos));
        size_t len = size_t(nl - start);
        pos += len + 1;
        std::string_view field(start, len);
        if (!field.empty() && field.back() == '\r') field.remove_suffix(1);
        if (field.empty()) break;  // the blank line ending the head
        if (++count > limits.max_headers) return fail(error, 431, "too many request header fields");
        if (field.front() == ' ' || field.front() == '\t') return fail(error, 400, "obsolete header line folding");
        size_t colon = field.find(':');
        if (colon == std::string_view::npos) return fail(error, 400, "malformed header field");
        std::string_view name = field.substr(0, colon);
        if (!is_token(name)) return fail(error, 400, "malformed header field name");
        std::string_view value = trim(field.substr(colon + 1));
        for (char c : value)
            if ((uint8_t(c) < 0x20 && c != '\t') || uint8_t(c) == 0x7f)
                return fail(error, 400, "control byte in header field value");
        switch (name.size()) {
            case 4:
                if (iequals(name, "host")) {
                    if (req.has_host) return fail(error, 400, "duplicate Host header");
                    req.has_host = true;
                    req.host = value;
                }
                break;
            case 5:
                if (iequals(name, "range")) req.range = value;
                break;
            case 8:
                if (iequals(name, "if-range")) req.if_range = value;
                break;
            case 10:
                if (iequals(name, "connection"))
                    for_each_list_element(value, [&](std::string_view token) {
                        if (iequals(token, "close")) close = true;
                        if (iequals(token, "keep-alive")) keep_alive = true;
                    });
                break;
            case 13:
                if (iequals(name, "if-none-match")) req.if_none_match = value;
                break;
            case 14:
                if (iequals(name, "content-length")) {
                    uint64_t length = 0;
                    if (!parse_u64(value, length)) return fail(error, 400, "malformed Content-Length");
                    if (req.has_content_length && length != req.content_length)
                        return fail(error, 400, "conflicting Content-Length headers");
                    req.has_content_length = true;
                    req.content_length = length;
                }
                break;
            case 17:
                if (iequals(name, "transfer-encoding")) req.has_transfer_encoding = true;
                break;
            case 30:
                if (iequals(name, "access-control-request-headers")) req.access_control_request_headers = value;
                break;
            default:
                break;
        }
    }
    if (req.version_minor == 1 && !req.has_host) return fail(error, 400, "HTTP/1.1 request without Host header");
    req.keep_alive = req.version_minor == 1 ? !close : (keep_alive && !close);
    scanned = 0;
    return ParseResult::Complete;
}

bool decode_target(std::string_view target, std::string& scratch, std::string_view& path, std::string& why) {
    if (target.size() >= 7 && (iequals(target.substr(0, 7), "http://") ||
                               (target.size() >= 8 && iequals(target.substr(0, 8), "https://")))) {
        // Absolute form: drop scheme and authority.
        size_t authority = target.find("//") + 2;
        size_t slash = target.find('/', authority);
        target = slash == std::string_view::npos ? std::string_view("/") : target.substr(slash);
    }
    size_t query = target.find('?');
    if (query != std::string_view::npos) target = target.substr(0, query);
    if (target.empty() || target.front() != '/') {
        why = "request target must be an absolute path";
        return false;
    }
    bool encoded = false;
    for (char c : target) {
        if (c == '\\') {
            why = "backslash in path";
            return false;
        }
        if (c == '#') {
            why = "fragment in request target";
            return false;
        }
        if (uint8_t(c) < 0x20 || uint8_t(c) == 0x7f) {
            why = "control byte in path";
            return false;
        }
        if (c == '%') encoded = true;
    }
    if (encoded) {
        scratch.clear();
        scratch.reserve(target.size());
        for (size_t i = 0; i < target.size(); ++i) {
            char c = target[i];
            if (c != '%') {
                scratch.push_back(c);
                continue;
            }
            int hi = i + 2 < target.size() ? hex_value(target[i + 1]) : -1;
            int lo = hi >= 0 ? hex_value(target[i + 2]) : -1;
            if (lo < 0) {
                why = "malformed percent-encoding in path";
                return false;
            }
            char v = char(hi * 16 + lo);
            if (v == '.' || v == '/' || v == '\\' || v == 0) {
                why = "percent-encoded dot, slash, backslash or NUL in path";
                return false;
            }
            if (uint8_t(v) < 0x20 || uint8_t(v) == 0x7f) {
                why = "percent-encoded control byte in path";
                return false;
            }
            scratch.push_back(v);
            i += 2;
        }
        path = scratch;
    } else {
        path = target;
    }
    // Segment rules.
    size_t start = 1;
    while (start <= path.size()) {
        size_t end = path.find('/', start);
        if (end == std::string_view::npos) end = path.size();
        std::string_view segment = path.substr(start, end - start);
        if (segment == "." || segment == "..") {
            why = "'.' or '..' segment in path";
            return false;
        }
        if (segment.empty() && end != path.size()) {
            why = "empty segment in path";
            return false;
        }
        start = end + 1;
    }
    return true;
}

RangeResult parse_range(std::string_view header, uint64_t size, uint64_t& first, uint64_t& last) {
    header = trim(header);
    size_t eq = header.find('=');
    if (eq == std::string_view::npos || !iequals(trim(header.substr(0, eq)), "bytes")) return RangeResult::None;
    std::string_view set = header.substr(eq + 1);
    size_t specs = 0;
    std::string_view spec;
    for_each_list_element(set, [&](std::string_view item) {
        ++specs;
        spec = item;
    });
    if (specs == 0) return RangeResult::Unsatisfiable;
    if (specs > 1) return RangeResult::Multiple;
    size_t dash = spec.find('-');
    if (dash == std::string_view::npos) return RangeResult::Unsatisfiable;
    std::string_view a = trim(spec.substr(0, dash)), b = trim(spec.substr(dash + 1));
    if (a.empty()) {  // suffix: the last n bytes
        uint64_t n = 0;
        if (!parse_u64(b, n) || n == 0 || size == 0) return RangeResult::Unsatisfiable;
        first = n >= size ? 0 : size - n;
        last = size - 1;
        return RangeResult::Single;
    }
    uint64_t from = 0;
    if (!parse_u64(a, from)) return RangeResult::Unsatisfiable;
    uint64_t to = UINT64_MAX;
    if (!b.empty() && !parse_u64(b, to)) return RangeResult::Unsatisfiable;
    if (to < from || from >= size) return RangeResult::Unsatisfiable;
    first = from;
    last = to >= size ? size - 1 : to;
    return RangeResult::Single;
}

bool etag_list_matches(std::string_view list, std::string_view etag) {
    if (etag.size() >= 2 && etag.compare(0, 2, "W/") == 0) etag.remove_prefix(2);
    bool match = false;
    for_each_list_element(list, [&](std::string_view tag) {
        if (tag == "*") match = true;
        if (tag.size() >= 2 && tag.compare(0, 2, "W/") == 0) tag.remove_prefix(2);
        if (tag == etag) match = true;
    });
    return match;
}

bool parse_node_key(std::string_view text, uint64_t& key) {
    if (text.size() > 2 && text[0] == '0' && (text[1] == 'x' || text[1] == 'X')) {
        text.remove_prefix(2);
        if (text.size() > 16) return false;
        uint64_t v = 0;
        for (char c : text) {
            int d = hex_value(c);
            if (d < 0) return false;
            v = v << 4 | uint64_t(d);
        }
        key = v;
        return true;
    }
    return parse_u64(text, key);
}

const char* status_reason(int status) {
    switch (status) {
        case 200: return "OK";
        case 204: return "No Content";
        case 206: return "Partial Content";
        case 304: return "Not Modified";
        case 400: return "Bad Request";
        case 404: return "Not Found";
        case 405: return "Method Not Allowed";
        case 408: return "Request Timeout";
        case 413: return "Content Too Large";
        case 414: return "URI Too Long";
        case 416: return "Range Not Satisfiable";
        case 431: return "Request Header Fields Too Large";
        case 500: return "Internal Server Error";
        case 501: return "Not Implemented";
        case 503: return "Service Unavailable";
        case 505: return "HTTP Version Not Supported";
    }
    return "Unknown";
}

std::string encode_path(std::string_view path) {
    static const char* kHex = "0123456789ABCDEF";
    std::string out;
    out.reserve(path.size());
    for (char c : path) {
        uint8_t u = uint8_t(c);
        if ((u >= 'a' && u <= 'z') || (u >= 'A' && u <= 'Z') || (u >= '0' && u <= '9') || c == '-' || c == '.' ||
            c == '_' || c == '~' || c == '/') {
            out.push_back(c);
        } else {
            out.push_back('%');
            out.push_back(kHex[u >> 4]);
            out.push_back(kHex[u & 15]);
        }
    }
    return out;
}

std::string printable(std::string_view text, size_t max_size) {
    static const char* kHex = "0123456789abcdef";
    std::string out;
    for (char c : text) {
        if (out.size() >= max_size) {
            out += "...";
            break;
        }
        uint8_t u = uint8_t(c);
        if (u < 0x20 || u >= 0x7f || c == '\\' || c == '"') {
            out += "\\x";
            out.push_back(kHex[u >> 4]);
            out.push_back(kHex[u & 15]);
        } else {
            out.push_back(c);
        }
    }
    return out;
}

std::string hex64(uint64_t value) {
    static const char* kHex = "0123456789abcdef";
    std::string out(16, '0');
    for (int i = 15; i >= 0; --i, value >>= 4) out[size_t(i)] = kHex[value & 15];
    return out;
}

std::string date_header(int64_t unix_seconds) {
    static const char* kDays[] = {"Sun", "Mon", "Tue", "Wed", "Thu", "Fri", "Sat"};
    static const char* kMonths[] = {"Jan", "Feb", "Mar", "Apr", "May", "Jun",
                                    "Jul", "Aug", "Sep", "Oct", "Nov", "Dec"};
    time_t t = time_t(unix_seconds);
    struct tm tm{};
    gmtime_r(&t, &tm);
    char buffer[64];
    int n = std::snprintf(buffer, sizeof buffer, "Date: %s, %02d %s %04d %02d:%02d:%02d GMT\r\n", kDays[tm.tm_wday % 7],
                          tm.tm_mday, kMonths[tm.tm_mon % 12], tm.tm_year + 1900, tm.tm_hour, tm.tm_min, tm.tm_sec);
    return std::string(buffer, size_t(n));
}

}  // namespace catpaq::http
