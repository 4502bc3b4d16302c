#pragma once
// The HTTP/1.1 wire format as far as the streaming server needs it: a strict, allocation-free
// request-head parser (RFC 9112), request-target sanitizing for the file routes, Range header
// parsing (RFC 9110 section 14) and small text helpers. Transport-independent, so the parser
// and path rules are the same whatever moves the bytes.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace catpaq::http {

struct Limits {
    size_t max_url = 8192;      // request-target bytes
    size_t max_header = 16384;  // header section bytes (after the request line)
    size_t max_headers = 100;   // header field count
};

struct Request {
    std::string_view method, target;
    int version_minor = 1;  // HTTP/1.<minor>
    std::string_view host, range, if_none_match, if_range, access_control_request_headers;
    bool has_host = false;
    bool has_transfer_encoding = false;
    bool has_content_length = false;
    uint64_t content_length = 0;
    bool keep_alive = true;  // from the version and Connection tokens
    size_t head_size = 0;    // bytes of the request line, the headers and the blank line
};

enum class ParseResult { Incomplete, Complete, Error };

struct ParseError {
    int status = 400;
    std::string message;
};

// Parses one request head from the start of [data, data + size). `scanned` carries, between
// calls on the same growing buffer, how far the search for the end of the head got (start at 0,
// reset after each complete request). Incomplete requests that already exceed the limits are
// errors (414 or 431), so a caller's buffer never needs more than max_request_head(limits).
ParseResult parse_request(const char* data, size_t size, const Limits& limits, Request& out, ParseError& error,
                          size_t& scanned);
size_t max_request_head(const Limits& limits);

// Checks a request-target and returns its decoded path (query removed) in `path`, which points
// either into `target` or into `scratch`. Refused (returns false, `why` says why): anything not
// origin-form or absolute-form, backslashes, control bytes, malformed or encoded dot, slash,
// backslash or NUL (%2e %2f %5c %00), "." and ".." segments, and empty segments ("//") other
// than a trailing one.
bool decode_target(std::string_view target, std::string& scratch, std::string_view& path, std::string& why);

enum class RangeResult { None, Single, Multiple, Unsatisfiable };
// Parses a Range header against a representation of `size` bytes. None: not a bytes range
// (ignored, 200). Multiple: more than one range (answered with the full body, 200).
// Unsatisfiable: malformed bytes range, or no byte of it inside the file (416).
RangeResult parse_range(std::string_view header, uint64_t size, uint64_t& first, uint64_t& last);

// True if an If-None-Match (or If-Range) list contains `etag` (weak comparison, "*" matches).
bool etag_list_matches(std::string_view list, std::string_view etag);

// Parses a node key: decimal u64 or 0x-prefixed hex. False on anything else or overflow.
bool parse_node_key(std::string_view text, uint64_t& key);

const char* status_reason(int status);
bool iequals(std::string_view a, std::string_view b);
// Percent-encodes a path for a URL, keeping '/' and unreserved characters.
std::string encode_path(std::string_view path);
// Makes request text safe for one log line (control and non-ASCII bytes become \xNN).
std::string printable(std::string_view text, size_t max_size = 512);
// 16 lowercase hex digits.
std::string hex64(uint64_t value);
// "Date: <IMF-fixdate>\r\n" for the given Unix time.
std::string date_header(int64_t unix_seconds);

}  // namespace catpaq::http
