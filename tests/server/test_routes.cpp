// The server's routes: catalog, details, prefix, nodes, raw files with Range, ETags, CORS, stats.
#include <algorithm>
#include <map>
#include <nlohmann/json.hpp>

#include "common_codec/archive.h"
#include "base/checksum.h"
#include "support.h"

namespace catpaq::test {
namespace {

using nlohmann::json;

class Routes : public ServerTest {};

std::string hex64(uint64_t v) {
    char buffer[17];
    std::snprintf(buffer, sizeof buffer, "%016llx", (unsigned long long)v);
    return buffer;
}

TEST_F(Routes, CatalogListsValidDatasetsWithKindSizeNodeCountBoundsAndUrls) {
    RawClient client(port());
    HttpResponse r = client.get("/api/datasets");
    ASSERT_EQ(r.status, 200);
    EXPECT_EQ(r.header("Content-Type"), "application/json");
    json catalog = json::parse(r.body);
    std::map<std::string, json> by_name;
    for (const json& d : catalog.at("datasets")) by_name[d.at("name").get<std::string>()] = d;
    std::vector<std::string> names;
    for (const auto& [name, d] : by_name) names.push_back(name);
    EXPECT_EQ(names, (std::vector<std::string>{"alpha", "corrupt_node", "inside_link", "sub/beta"}));

    const json& alpha = by_name["alpha"];
    ArchiveReader reader(fixture->root() + "/alpha.cpq");
    EXPECT_EQ(alpha.at("kind"), "catp");
    EXPECT_EQ(alpha.at("file_size").get<uint64_t>(), reader.size());
    EXPECT_EQ(alpha.at("node_count").get<uint64_t>(), fixture->alpha.size());
    for (int i = 0; i < 3; ++i) {
        EXPECT_EQ(alpha.at("bounds").at("min")[i].get<double>(), Fixture::kMin[i]);
        EXPECT_EQ(alpha.at("bounds").at("max")[i].get<double>(), Fixture::kMax[i]);
    }
    EXPECT_EQ(alpha.at("urls").at("details"), "/api/datasets/alpha");
    EXPECT_EQ(alpha.at("urls").at("prefix"), "/api/datasets/alpha/prefix");
    EXPECT_EQ(alpha.at("urls").at("nodes"), "/api/datasets/alpha/nodes/{key}");
    EXPECT_EQ(alpha.at("urls").at("file"), "/files/alpha.cpq");

    const json& beta = by_name["sub/beta"];
    EXPECT_EQ(beta.at("kind"), "aqp");
    EXPECT_FALSE(beta.contains("bounds"));  // its meta is not AQP's: served without a description
    EXPECT_EQ(beta.at("urls").at("file"), "/files/sub/beta.cpq");
}

// The server core knows no format: without any describer it serves every archive, CATP and AQP
// alike, by its container alone. Catalog and details have no bounds or format part; prefix,
// nodes and ranges are the file's bytes.
TEST_F(Routes, WithoutDescribersEveryKindIsServedByItsContainerAlone) {
    RunningServer bare(fixture->root(), ServerSettings{}, false);
    RawClient client(bare.port);
    json catalog = json::parse(client.get("/api/datasets").body);
    EXPECT_EQ(catalog.at("datasets").size(), 4u);
    for (const json& d : catalog.at("datasets")) EXPECT_FALSE(d.contains("bounds")) << d.dump();
    json alpha = json::parse(client.get("/api/datasets/alpha").body);
    EXPECT_EQ(alpha.at("kind"), "catp");
    EXPECT_FALSE(alpha.contains("catp"));
    EXPECT_FALSE(alpha.contains("meta_error"));
    EXPECT_EQ(json::parse(client.get("/api/datasets/sub/beta").body).at("kind"), "aqp");
    for (const std::string name : {"alpha", "sub/beta"}) {
        SCOPED_TRACE(name);
        const std::string path = fixture->root() + "/" + name + ".cpq";
        const std::string file = read_whole_file(path);
        ArchiveReader reader(path);
        EXPECT_TRUE(client.get("/api/datasets/" + name + "/prefix").body ==
                    file.substr(0, archive_first_request_size(reader.header(), reader.entries())));
        for (const ArchiveEntry& e : reader.entries()) {
            HttpResponse node = client.get(node_path(name, e.key));
            EXPECT_EQ(node.status, 200);
            EXPECT_TRUE(node.body == file.substr(e.offset, e.size)) << e.key;
            if (e.size == 0) continue;
            HttpResponse range = client.get("/files/" + name + ".cpq", "Range: bytes=" + std::to_string(e.offset) + "-" +
                                                                           std::to_string(e.offset + e.size - 1) + "\r\n");
            EXPECT_EQ(range.status, 206);
            EXPECT_TRUE(range.body == file.substr(e.offset, e.size)) << e.key;
        }
    }
}

TEST_F(Routes, CorruptHeaderDatasetIsSkippedAtStartupWithLoggedReason) {
    std::vector<std::string> names = running->server->dataset_names();
    EXPECT_EQ(std::count(names.begin(), names.end(), "corrupt_header"), 0);
    EXPECT_TRUE(running->log.contains("corrupt_header", "header checksum mismatch"));
    EXPECT_TRUE(running->log.contains("skipping dataset 'fake'", "too short to be a catpaq dataset"));
    RawClient client(port());
    EXPECT_EQ(client.get("/api/datasets/corrupt_header").status, 404);
    EXPECT_EQ(client.get("/files/corrupt_header.cpq").status, 404);
}

TEST_F(Routes, DatasetDetailsReportHeaderFieldsLevelsAndPayloadBytes) {
    RawClient client(port());
    HttpResponse r = client.get("/api/datasets/alpha");
    ASSERT_EQ(r.status, 200);
    json d = json::parse(r.body);
    ArchiveReader reader(fixture->root() + "/alpha.cpq");
    const ArchiveHeader& h = reader.header();
    EXPECT_EQ(d.at("name"), "alpha");
    EXPECT_EQ(d.at("version").get<uint32_t>(), h.version);
    EXPECT_EQ(d.at("meta_offset").get<uint64_t>(), h.meta_offset);
    EXPECT_EQ(d.at("meta_size").get<uint64_t>(), h.meta_size);
    EXPECT_EQ(d.at("index_offset").get<uint64_t>(), h.index_offset);
    EXPECT_EQ(d.at("index_size").get<uint64_t>(), h.index_size);
    EXPECT_EQ(d.at("node_count").get<uint64_t>(), h.node_count);
    EXPECT_EQ(d.at("prefix_size").get<uint64_t>(), reader.prefix_size());
    EXPECT_EQ(d.at("first_request_size").get<uint64_t>(), archive_first_request_size(h, reader.entries()));
    EXPECT_EQ(d.at("meta_checksum"), hex64(h.meta_checksum));
    EXPECT_EQ(d.at("index_checksum"), hex64(h.index_checksum));
    std::map<uint64_t, std::pair<uint64_t, uint64_t>> levels;
    uint64_t payload = 0;
    for (const BuiltNode& n : fixture->alpha) {
        levels[n.level].first += 1;
        levels[n.level].second += n.bytes.size();
        payload += n.bytes.size();
    }
    EXPECT_EQ(d.at("payload_bytes").get<uint64_t>(), payload);
    ASSERT_EQ(d.at("levels").size(), levels.size());
    for (const json& level : d.at("levels")) {
        auto expected = levels.at(level.at("level").get<uint64_t>());
        EXPECT_EQ(level.at("nodes").get<uint64_t>(), expected.first);
        EXPECT_EQ(level.at("bytes").get<uint64_t>(), expected.second);
    }
    EXPECT_EQ(d.at("catp").at("leaf_level").get<int>(), 3);

    HttpResponse sub = client.get("/api/datasets/sub/beta");
    ASSERT_EQ(sub.status, 200);
    EXPECT_EQ(json::parse(sub.body).at("node_count").get<size_t>(), fixture->beta.size());
    EXPECT_EQ(client.get("/api/datasets/nope").status, 404);
}

// The first request: header, meta and index, then the level-0 nodes that fit whole in 64 KiB,
// so that a client draws the first frame from it (here level 0 is larger: it brings some).
TEST_F(Routes, PrefixIsHeaderMetaIndexAndLevelZeroBytesOfTheFile) {
    RawClient client(port());
    HttpResponse r = client.get("/api/datasets/alpha/prefix");
    ASSERT_EQ(r.status, 200);
    ArchiveReader reader(fixture->root() + "/alpha.cpq");
    std::string file = read_whole_file(fixture->root() + "/alpha.cpq");
    // Level 0's nodes follow the index; those that fit whole in 64 KiB come along.
    uint64_t end = reader.prefix_size();
    size_t nodes = 0;
    for (const ArchiveEntry& e : reader.entries()) {
        if (e.level != 0 || e.offset + e.size > kFirstRequestBytes) break;
        ASSERT_EQ(e.offset, end);
        end += e.size;
        nodes++;
    }
    ASSERT_GT(nodes, 0u);
    EXPECT_EQ(r.body, file.substr(0, end));
    EXPECT_EQ(r.header("Content-Type"), "application/octet-stream");
    std::string etag = r.header("ETag");
    ASSERT_FALSE(etag.empty());
    EXPECT_EQ(client.get("/api/datasets/alpha/prefix", "If-None-Match: " + etag + "\r\n").status, 304);
}

TEST_F(Routes, EveryNodeIsByteExactAgainstArchiveReader) {
    ArchiveReader reader(fixture->root() + "/alpha.cpq");
    RawClient client(port());
    for (size_t i = 0; i < reader.entries().size(); ++i) {
        const ArchiveEntry& e = reader.entries()[i];
        std::string error;
        const uint8_t* bytes = reader.node(i, &error);
        ASSERT_NE(bytes, nullptr) << error;
        HttpResponse r = client.get(node_path("alpha", e.key));
        ASSERT_EQ(r.status, 200) << e.key;
        EXPECT_EQ(r.body, std::string(reinterpret_cast<const char*>(bytes), e.size)) << e.key;
        EXPECT_EQ(r.header("Content-Length"), std::to_string(e.size));
        EXPECT_EQ(r.header("Content-Type"), "application/octet-stream");
    }
    // The sub-directory dataset and the in-root symlink to it.
    for (const BuiltNode& n : fixture->beta) {
        EXPECT_EQ(client.get(node_path("sub/beta", n.key)).body, to_string(n.bytes));
        EXPECT_EQ(client.get(node_path("inside_link", n.key)).body, to_string(n.bytes));
    }
}

TEST_F(Routes, EmptyAndTwoMegabyteNodesAreServedExactly) {
    RawClient client(port());
    HttpResponse empty = client.get(node_path("alpha", Fixture::kEmptyKey));
    EXPECT_EQ(empty.status, 200);
    EXPECT_EQ(empty.header("Content-Length"), "0");
    EXPECT_TRUE(empty.body.empty());
    HttpResponse big = client.get(node_path("alpha", Fixture::kBigKey));
    EXPECT_EQ(big.status, 200);
    EXPECT_EQ(big.body.size(), size_t(2) << 20);
    EXPECT_TRUE(big.body == to_string(alpha_node(Fixture::kBigKey).bytes));
}

TEST_F(Routes, NodeKeyAcceptsDecimalAndHexAndRejectsMalformedKeys) {
    RawClient client(port());
    const std::string expected = to_string(alpha_node(Fixture::kHugeKey).bytes);
    EXPECT_EQ(client.get("/api/datasets/alpha/nodes/" + std::to_string(Fixture::kHugeKey)).body, expected);
    EXPECT_EQ(client.get("/api/datasets/alpha/nodes/0xf000000000000001").body, expected);
    EXPECT_EQ(client.get("/api/datasets/alpha/nodes/0XF000000000000001").body, expected);
    EXPECT_EQ(client.get("/api/datasets/alpha/nodes/12abc").status, 400);
    EXPECT_EQ(client.get("/api/datasets/alpha/nodes/").status, 400);
    EXPECT_EQ(client.get("/api/datasets/alpha/nodes/-1").status, 400);
    EXPECT_EQ(client.get("/api/datasets/alpha/nodes/99999999999999999999").status, 400);  // > 2^64
    EXPECT_EQ(client.get("/api/datasets/alpha/nodes/0x10000000000000000").status, 400);
    EXPECT_EQ(client.get("/api/datasets/alpha/nodes/123456789").status, 404);
    EXPECT_EQ(client.get("/api/datasets/nope/nodes/1").status, 404);
}

TEST_F(Routes, CorruptNodeGives500AndALogLineWhileTheOtherNodesStillServe) {
    RawClient client(port());
    HttpResponse bad = client.get(node_path("corrupt_node", Fixture::kCorruptKey));
    EXPECT_EQ(bad.status, 500);
    EXPECT_NE(bad.body.find("corrupt"), std::string::npos);
    EXPECT_TRUE(running->log.contains("error", "checksum mismatch"));
    for (const BuiltNode& n : fixture->corrupt) {
        if (n.key == Fixture::kCorruptKey) continue;
        HttpResponse ok = client.get(node_path("corrupt_node", n.key));  // same connection still works
        EXPECT_EQ(ok.status, 200);
        EXPECT_EQ(ok.body, to_string(n.bytes));
    }
}

TEST_F(Routes, NodeETagIsItsChecksumAndIfNoneMatchGives304) {
    RawClient client(port());
    const BuiltNode& node = alpha_node(fixture->alpha[3].key);
    std::string etag = "\"" + hex64(archive_node_checksum(kArchiveVersion, node.bytes.data(), node.bytes.size())) + "\"";
    HttpResponse r = client.get(node_path("alpha", node.key));
    EXPECT_EQ(r.header("ETag"), etag);
    EXPECT_EQ(r.header("Cache-Control"), "public, max-age=31536000, immutable");
    HttpResponse cached = client.get(node_path("alpha", node.key), "If-None-Match: " + etag + "\r\n");
    EXPECT_EQ(cached.status, 304);
    EXPECT_TRUE(cached.body.empty());
    EXPECT_EQ(cached.header("ETag"), etag);
    EXPECT_EQ(client.get(node_path("alpha", node.key), "If-None-Match: \"x\", W/" + etag + "\r\n").status, 304);
    EXPECT_EQ(client.get(node_path("alpha", node.key), "If-None-Match: *\r\n").status, 304);
    HttpResponse other = client.get(node_path("alpha", node.key), "If-None-Match: \"0000000000000000\"\r\n");
    EXPECT_EQ(other.status, 200);
    EXPECT_EQ(other.body, to_string(node.bytes));
}

TEST_F(Routes, ResponsesAreNeverCompressedEvenWhenTheClientAcceptsGzip) {
    RawClient client(port());
    const BuiltNode& node = fixture->alpha[5];
    for (const std::string& target : {node_path("alpha", node.key), std::string("/api/datasets"),
                                      std::string("/files/alpha.cpq")}) {
        HttpResponse r = client.get(target, "Accept-Encoding: gzip, deflate, br\r\n");
        EXPECT_EQ(r.status, 200);
        EXPECT_FALSE(r.has("Content-Encoding")) << target;
    }
    EXPECT_EQ(client.get(node_path("alpha", node.key), "Accept-Encoding: gzip\r\n").body, to_string(node.bytes));
}

class Files : public ServerTest {
protected:
    void SetUp() override { file = read_whole_file(fixture->root() + "/alpha.cpq"); }
    std::string file;
};

TEST_F(Files, WholeFileHasAcceptRangesAndETag) {
    RawClient client(port());
    HttpResponse r = client.get("/files/alpha.cpq");
    ASSERT_EQ(r.status, 200);
    EXPECT_TRUE(r.body == file);
    EXPECT_EQ(r.header("Accept-Ranges"), "bytes");
    EXPECT_FALSE(r.header("ETag").empty());
    EXPECT_EQ(client.get("/files/alpha.cpq", "If-None-Match: " + r.header("ETag") + "\r\n").status, 304);
    EXPECT_EQ(client.get("/files/sub/beta.cpq").body, read_whole_file(fixture->root() + "/sub/beta.cpq"));
}

TEST_F(Files, ClosedRangeGives206WithContentRange) {
    RawClient client(port());
    HttpResponse r = client.get("/files/alpha.cpq", "Range: bytes=100-299\r\n");
    ASSERT_EQ(r.status, 206);
    EXPECT_EQ(r.header("Content-Range"), "bytes 100-299/" + std::to_string(file.size()));
    EXPECT_EQ(r.header("Content-Length"), "200");
    EXPECT_EQ(r.body, file.substr(100, 200));
    // An end past the file is clipped to the last byte.
    HttpResponse clipped = client.get("/files/alpha.cpq", "Range: bytes=1000-99999999999\r\n");
    ASSERT_EQ(clipped.status, 206);
    EXPECT_EQ(clipped.header("Content-Range"),
              "bytes 1000-" + std::to_string(file.size() - 1) + "/" + std::to_string(file.size()));
    EXPECT_TRUE(clipped.body == file.substr(1000));
}

TEST_F(Files, OpenEndedRangeGives206ToTheEnd) {
    RawClient client(port());
    size_t from = file.size() - 5000;
    HttpResponse r = client.get("/files/alpha.cpq", "Range: bytes=" + std::to_string(from) + "-\r\n");
    ASSERT_EQ(r.status, 206);
    EXPECT_EQ(r.header("Content-Range"), "bytes " + std::to_string(from) + "-" + std::to_string(file.size() - 1) +
                                             "/" + std::to_string(file.size()));
    EXPECT_EQ(r.body, file.substr(from));
}

TEST_F(Files, SuffixRangeGives206WithTheLastBytes) {
    RawClient client(port());
    HttpResponse r = client.get("/files/alpha.cpq", "Range: bytes=-300\r\n");
    ASSERT_EQ(r.status, 206);
    EXPECT_EQ(r.header("Content-Range"), "bytes " + std::to_string(file.size() - 300) + "-" +
                                             std::to_string(file.size() - 1) + "/" + std::to_string(file.size()));
    EXPECT_EQ(r.body, file.substr(file.size() - 300));
    HttpResponse whole = client.get("/files/alpha.cpq", "Range: bytes=-999999999\r\n");  // longer than the file
    EXPECT_EQ(whole.status, 206);
    EXPECT_TRUE(whole.body == file);
}

TEST_F(Files, UnsatisfiableRangesGive416WithStarContentRange) {
    RawClient client(port());
    const std::string star = "bytes */" + std::to_string(file.size());
    for (const std::string& range : {"bytes=" + std::to_string(file.size()) + "-", std::string("bytes=500-100"),
                                     std::string("bytes=-0"), std::string("bytes=abc-def"), std::string("bytes=")}) {
        HttpResponse r = client.get("/files/alpha.cpq", "Range: " + range + "\r\n");
        EXPECT_EQ(r.status, 416) << range;
        EXPECT_EQ(r.header("Content-Range"), star) << range;
    }
    EXPECT_EQ(client.get("/api/datasets").status, 200);  // the connection is still usable
}

TEST_F(Files, MultipleRangesAndOtherUnitsAreAnsweredWithTheFullFile) {
    RawClient client(port());
    HttpResponse multi = client.get("/files/alpha.cpq", "Range: bytes=0-9, 20-29\r\n");
    EXPECT_EQ(multi.status, 200);
    EXPECT_TRUE(multi.body == file);
    HttpResponse items = client.get("/files/alpha.cpq", "Range: items=0-9\r\n");
    EXPECT_EQ(items.status, 200);
    EXPECT_EQ(items.body.size(), file.size());
}

TEST_F(Files, IfRangeAppliesTheRangeOnlyForTheCurrentETag) {
    RawClient client(port());
    std::string etag = client.get("/files/alpha.cpq").header("ETag");
    EXPECT_EQ(client.get("/files/alpha.cpq", "Range: bytes=0-9\r\nIf-Range: " + etag + "\r\n").status, 206);
    HttpResponse stale = client.get("/files/alpha.cpq", "Range: bytes=0-9\r\nIf-Range: \"stale\"\r\n");
    EXPECT_EQ(stale.status, 200);
    EXPECT_EQ(stale.body.size(), file.size());
}

TEST_F(Files, HeadHasTheHeadersOfGetAndNoBodyOnEveryRoute) {
    RawClient client(port());
    const BuiltNode& node = fixture->alpha[7];
    for (const std::string& target :
         {node_path("alpha", node.key), std::string("/files/alpha.cpq"), std::string("/api/datasets"),
          std::string("/api/datasets/alpha"), std::string("/api/datasets/alpha/prefix"), std::string("/stats"),
          std::string("/metrics"), std::string("/api/datasets/nope")}) {
        HttpResponse get = client.get(target);
        HttpResponse head = client.request("HEAD", target);  // read() expects no body after HEAD
        EXPECT_EQ(head.status, get.status) << target;
        EXPECT_TRUE(head.body.empty());
        if (target != "/stats" && target != "/metrics") {  // their size changes between requests
            EXPECT_EQ(head.header("Content-Length"), get.header("Content-Length")) << target;
        }
    }
    HttpResponse range = client.request("HEAD", "/files/alpha.cpq", "Range: bytes=10-19\r\n");
    EXPECT_EQ(range.status, 206);
    EXPECT_EQ(range.header("Content-Length"), "10");
    EXPECT_EQ(range.header("Content-Range"), "bytes 10-19/" + std::to_string(file.size()));
    // Had a body followed any HEAD response, this exact read would see it instead.
    EXPECT_EQ(client.get(node_path("alpha", node.key)).body, to_string(node.bytes));
}

TEST_F(Routes, EveryResponseCarriesCorsHeaders) {
    RawClient client(port());
    for (const std::string& target :
         {node_path("alpha", fixture->alpha[0].key), std::string("/files/alpha.cpq"), std::string("/nope"),
          std::string("/api/datasets")}) {
        HttpResponse r = client.get(target, "Origin: https://viewer.example\r\n");
        EXPECT_EQ(r.header("Access-Control-Allow-Origin"), "*") << target;
        std::string exposed = r.header("Access-Control-Expose-Headers");
        for (const char* h : {"Content-Range", "ETag", "Content-Length"})
            EXPECT_NE(exposed.find(h), std::string::npos) << target << " " << h;
    }
}

TEST_F(Routes, OptionsPreflightAllowsCrossOriginRangeRequests) {
    RawClient client(port());
    HttpResponse r = client.request("OPTIONS", "/files/alpha.cpq",
                                    "Origin: https://viewer.example\r\nAccess-Control-Request-Method: GET\r\n"
                                    "Access-Control-Request-Headers: range, if-none-match\r\n");
    EXPECT_EQ(r.status, 204);
    EXPECT_EQ(r.header("Access-Control-Allow-Origin"), "*");
    EXPECT_NE(r.header("Access-Control-Allow-Methods").find("GET"), std::string::npos);
    EXPECT_NE(r.header("Access-Control-Allow-Headers").find("range"), std::string::npos);
    EXPECT_EQ(client.request("OPTIONS", "*").status, 204);
    EXPECT_EQ(client.request("OPTIONS", "/no/such/route").status, 404);
}

TEST_F(Routes, UnknownRoutesGive404AndOtherMethodsGive405WithAllow) {
    RawClient client(port());
    EXPECT_EQ(client.get("/nope").status, 404);
    EXPECT_EQ(client.get("/api").status, 404);
    EXPECT_EQ(client.get("/api/datasets/alpha/unknown").status, 404);
    EXPECT_EQ(client.get("/files/").status, 404);
    for (const char* method : {"POST", "PUT", "DELETE", "PATCH", "BREW"}) {
        HttpResponse r = client.request(method, "/api/datasets");
        EXPECT_EQ(r.status, 405) << method;
        EXPECT_EQ(r.header("Allow"), "GET, HEAD, OPTIONS");
    }
    // A request body is read and discarded: the connection stays in sync.
    client.send("POST /api/datasets HTTP/1.1\r\nHost: x\r\nContent-Length: 11\r\n\r\nhello world");
    HttpResponse posted;
    ASSERT_TRUE(client.read(posted));
    EXPECT_EQ(posted.status, 405);
    EXPECT_EQ(client.get("/api/datasets").status, 200);
}

TEST_F(Routes, StatsCountRequestsByRouteAndStatusAndBytesSent) {
    RawClient client(port());
    json before = json::parse(client.get("/stats").body);
    for (int i = 0; i < 3; ++i) ASSERT_EQ(client.get(node_path("alpha", fixture->alpha[size_t(i)].key)).status, 200);
    ASSERT_EQ(client.get(node_path("alpha", 123456789)).status, 404);
    ASSERT_EQ(client.get("/files/alpha.cpq", "Range: bytes=0-9\r\n").status, 206);
    json after = json::parse(client.get("/stats").body);
    auto count = [](const json& j, const char* route, const char* status) -> uint64_t {
        if (!j.at("requests").contains(route) || !j.at("requests").at(route).contains(status)) return 0;
        return j.at("requests").at(route).at(status).get<uint64_t>();
    };
    EXPECT_EQ(count(after, "node", "200") - count(before, "node", "200"), 3u);
    EXPECT_EQ(count(after, "node", "404") - count(before, "node", "404"), 1u);
    EXPECT_EQ(count(after, "files", "206") - count(before, "files", "206"), 1u);
    EXPECT_EQ(count(after, "stats", "200") - count(before, "stats", "200"), 1u);
    EXPECT_GT(after.at("bytes_sent").get<uint64_t>(), before.at("bytes_sent").get<uint64_t>() + 10);
    EXPECT_GE(after.at("open_connections").get<int64_t>(), 1);
    EXPECT_GE(after.at("uptime_seconds").get<double>(), 0.0);
    EXPECT_EQ(after.at("datasets").get<int>(), 4);
}

TEST_F(Routes, MetricsArePrometheusTextOfTheSameCounters) {
    RawClient client(port());
    ASSERT_EQ(client.get(node_path("alpha", fixture->alpha[0].key)).status, 200);
    HttpResponse r = client.get("/metrics");
    ASSERT_EQ(r.status, 200);
    EXPECT_EQ(r.header("Content-Type").rfind("text/plain; version=0.0.4", 0), 0u);
    EXPECT_NE(r.body.find("# TYPE catpaq_requests_total counter\n"), std::string::npos);
    EXPECT_NE(r.body.find("\ncatpaq_requests_total{route=\"node\",status=\"200\"} "), std::string::npos);
    EXPECT_NE(r.body.find("# TYPE catpaq_open_connections gauge\ncatpaq_open_connections "), std::string::npos);
    EXPECT_NE(r.body.find("\ncatpaq_bytes_sent_total "), std::string::npos);
    EXPECT_NE(r.body.find("\ncatpaq_uptime_seconds "), std::string::npos);
    // Every sample line is "name{labels} value" or "name value".
    size_t pos = 0;
    while (pos < r.body.size()) {
        size_t eol = r.body.find('\n', pos);
        ASSERT_NE(eol, std::string::npos);
        std::string line = r.body.substr(pos, eol - pos);
        pos = eol + 1;
        if (line.rfind("# ", 0) == 0) continue;
        size_t space = line.rfind(' ');
        ASSERT_NE(space, std::string::npos) << line;
        EXPECT_EQ(line.rfind("catpaq_", 0), 0u) << line;
        std::string value = line.substr(space + 1);
        EXPECT_FALSE(value.empty());
        EXPECT_EQ(value.find_first_not_of("0123456789."), std::string::npos) << line;
    }
}

}  // namespace
}  // namespace catpaq::test
