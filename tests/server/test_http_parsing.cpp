// White-box tests of the server's HTTP helpers (server/src/http.h): request heads, target
// sanitizing, Range and ETag parsing, node keys.
#include <gtest/gtest.h>

#include "http.h"

namespace catpaq::http {
namespace {

ParseResult parse(const std::string& text, Request& request, ParseError& error) {
    size_t scanned = 0;
    Limits limits;
    return parse_request(text.data(), text.size(), limits, request, error, scanned);
}

TEST(HttpParsing, CompleteHeadYieldsMethodTargetVersionAndKnownHeaders) {
    Request r;
    ParseError e;
    std::string text =
        "GET /files/a.cpq HTTP/1.1\r\nHost: h\r\nRange:  bytes=1-2 \r\nIf-None-Match: \"x\"\r\n"
        "connection: Keep-Alive, CLOSE\r\n\r\nNEXT";
    ASSERT_EQ(parse(text, r, e), ParseResult::Complete);
    EXPECT_EQ(r.method, "GET");
    EXPECT_EQ(r.target, "/files/a.cpq");
    EXPECT_EQ(r.version_minor, 1);
    EXPECT_EQ(r.host, "h");
    EXPECT_EQ(r.range, "bytes=1-2");
    EXPECT_EQ(r.if_none_match, "\"x\"");
    EXPECT_FALSE(r.keep_alive);
    EXPECT_EQ(r.head_size, text.size() - 4);
}

TEST(HttpParsing, IncompleteHeadsAskForMoreAtEveryCutPoint) {
    std::string text = "GET / HTTP/1.1\r\nHost: h\r\n\r\n";
    for (size_t cut = 0; cut < text.size(); ++cut) {
        Request r;
        ParseError e;
        size_t scanned = 0;
        Limits limits;
        EXPECT_EQ(parse_request(text.data(), cut, limits, r, e, scanned), ParseResult::Incomplete) << cut;
        // Resuming with the whole text from the saved scan position finds the end.
        EXPECT_EQ(parse_request(text.data(), text.size(), limits, r, e, scanned), ParseResult::Complete) << cut;
        EXPECT_EQ(r.head_size, text.size());
    }
}

TEST(HttpParsing, LimitsGive414And431BeforeTheHeadIsComplete) {
    Limits limits;
    limits.max_url = 100;
    limits.max_header = 200;
    Request r;
    ParseError e;
    size_t scanned = 0;
    std::string long_line = "GET /" + std::string(400, 'a');
    EXPECT_EQ(parse_request(long_line.data(), long_line.size(), limits, r, e, scanned), ParseResult::Error);
    EXPECT_EQ(e.status, 414);
    std::string long_headers = "GET / HTTP/1.1\r\nX: " + std::string(400, 'b');
    scanned = 0;
    EXPECT_EQ(parse_request(long_headers.data(), long_headers.size(), limits, r, e, scanned), ParseResult::Error);
    EXPECT_EQ(e.status, 431);
    EXPECT_LE(long_headers.size(), max_request_head(limits) + 400);
}

TEST(HttpParsing, DecodeTargetRefusesUnsafePathsAndDecodesSafeOnes) {
    std::string scratch, why;
    std::string_view path;
    ASSERT_TRUE(decode_target("/api/datasets/a%20b/nodes/1?x=1", scratch, path, why));
    EXPECT_EQ(path, "/api/datasets/a b/nodes/1");
    ASSERT_TRUE(decode_target("https://host:8080/files/x.cpq", scratch, path, why));
    EXPECT_EQ(path, "/files/x.cpq");
    for (const char* bad : {"/a/../b", "/..", "/a/./b", "/%2e%2e/x", "/%2E/x", "/a%2fb", "/a%2Fb", "/a%5cb", "/a%00",
                            "/a\\b", "//etc/passwd", "/a//b", "relative", "", "/a%", "/a%4", "/a%g0", "/a%0a",
                            "/a#frag"}) {
        EXPECT_FALSE(decode_target(bad, scratch, path, why)) << bad;
        EXPECT_FALSE(why.empty());
    }
}

TEST(HttpParsing, RangeFormsAreParsedAgainstTheFileSize) {
    uint64_t first = 0, last = 0;
    EXPECT_EQ(parse_range("bytes=0-99", 1000, first, last), RangeResult::Single);
    EXPECT_EQ(first, 0u);
    EXPECT_EQ(last, 99u);
    EXPECT_EQ(parse_range("bytes=900-", 1000, first, last), RangeResult::Single);
    EXPECT_EQ(first, 900u);
    EXPECT_EQ(last, 999u);
    EXPECT_EQ(parse_range("bytes=-10", 1000, first, last), RangeResult::Single);
    EXPECT_EQ(first, 990u);
    EXPECT_EQ(last, 999u);
    EXPECT_EQ(parse_range("bytes=-5000", 1000, first, last), RangeResult::Single);
    EXPECT_EQ(first, 0u);
    EXPECT_EQ(parse_range("bytes=5-99999", 1000, first, last), RangeResult::Single);
    EXPECT_EQ(last, 999u);
    EXPECT_EQ(parse_range("Bytes = 1-2", 1000, first, last), RangeResult::Single);
    EXPECT_EQ(parse_range("bytes=1000-", 1000, first, last), RangeResult::Unsatisfiable);
    EXPECT_EQ(parse_range("bytes=5-4", 1000, first, last), RangeResult::Unsatisfiable);
    EXPECT_EQ(parse_range("bytes=-0", 1000, first, last), RangeResult::Unsatisfiable);
    EXPECT_EQ(parse_range("bytes=x-1", 1000, first, last), RangeResult::Unsatisfiable);
    EXPECT_EQ(parse_range("bytes=18446744073709551616-", 1000, first, last), RangeResult::Unsatisfiable);
    EXPECT_EQ(parse_range("bytes=0-1,4-5", 1000, first, last), RangeResult::Multiple);
    EXPECT_EQ(parse_range("items=0-1", 1000, first, last), RangeResult::None);
}

TEST(HttpParsing, ETagListsMatchWeaklyAndStar) {
    EXPECT_TRUE(etag_list_matches("\"a\"", "\"a\""));
    EXPECT_TRUE(etag_list_matches("\"b\", W/\"a\"", "\"a\""));
    EXPECT_TRUE(etag_list_matches("*", "\"a\""));
    EXPECT_FALSE(etag_list_matches("\"b\"", "\"a\""));
    EXPECT_FALSE(etag_list_matches("", "\"a\""));
}

TEST(HttpParsing, NodeKeysAreDecimalOrHexU64) {
    uint64_t key = 0;
    EXPECT_TRUE(parse_node_key("18446744073709551615", key));
    EXPECT_EQ(key, UINT64_MAX);
    EXPECT_TRUE(parse_node_key("0xffffffffffffffff", key));
    EXPECT_EQ(key, UINT64_MAX);
    EXPECT_TRUE(parse_node_key("0x1A", key));
    EXPECT_EQ(key, 26u);
    for (const char* bad : {"", "0x", "18446744073709551616", "0x10000000000000000", "1 ", "+1", "0b1", "1e3"})
        EXPECT_FALSE(parse_node_key(bad, key)) << bad;
}

}  // namespace
}  // namespace catpaq::http
