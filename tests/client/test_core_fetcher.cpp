// Node sources and the fetcher: exact bytes from a local file and over HTTP (our server's routes
// and raw Range requests, against a small in-test server), checksum failures and transport
// errors retried with backoff, a server restart survived, stale requests cancelled.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <random>
#include <set>

#include "base/checksum.h"
#include "base/error.h"
#include "catp/dataset.h"
#include "catp_client/catp_format.h"
#include "client/fetcher.h"
#include "client/hierarchy.h"
#include "common_codec/archive.h"
#include "test_core_support.h"

using namespace catpaq;
using Fault = catpaq::test::TestHttpServer::Fault;

namespace {

// Waits (polling, generous deadline: a safety net, not a timing assertion) until `done()`.
template <class F>
bool eventually(F done, int seconds = 60) {
    auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
    while (!done()) {
        if (std::chrono::steady_clock::now() > deadline) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return true;
}

struct Dataset;
const Dataset& dataset();

// The CATP decoder of the test dataset: the fetcher decodes what it verified.
FetcherSettings decoding();

FetcherSettings fast_retries() {
    FetcherSettings s = decoding();
    s.backoff_initial = std::chrono::milliseconds(2);
    s.backoff_max = std::chrono::milliseconds(20);
    s.max_attempts = 4;
    s.failed_retry_delay = std::chrono::milliseconds(30);
    return s;
}

struct Dataset {
    std::string path = test::sphere_dataset();
    std::vector<uint8_t> bytes = test::read_file(path);
    CatpFile file{path};
    std::unique_ptr<CatpFormat> format = test::open_catp_format(path);
    const Hierarchy& h = format->hierarchy();

    std::vector<uint8_t> node_bytes(const ArchiveEntry& e) const {
        return std::vector<uint8_t>(bytes.begin() + long(e.offset), bytes.begin() + long(e.offset + e.size));
    }
    std::vector<FetchRequest> all_requests() const {
        std::vector<FetchRequest> out;
        for (const HierarchyNode& n : h.nodes())
            if (n.has_data) out.push_back(FetchRequest::of(n));
        return out;
    }
};

const Dataset& dataset() {
    static Dataset d;
    return d;
}

FetcherSettings decoding() {
    FetcherSettings s;
    s.decode = format_decoder(*dataset().format);
    return s;
}

// Fetches every node through a source with the non-blocking interface, all submitted at once.
void expect_exact_nodes(NodeSource& source, const Dataset& d) {
    std::map<uint64_t, const ArchiveEntry*> by_id;
    uint64_t id = 1;
    for (const ArchiveEntry& e : d.file.index().entries()) {
        SourceRequest r;
        r.id = id;
        r.kind = SourceRequest::Kind::Node;
        r.key = e.key;
        r.offset = e.offset;
        r.size = e.size;
        by_id[id++] = &e;
        source.submit(r);
    }
    std::vector<SourceResult> results;
    ASSERT_TRUE(eventually([&] {
        source.poll(results, 10);
        return results.size() == by_id.size();
    }));
    std::set<uint64_t> seen;
    for (const SourceResult& r : results) {
        ASSERT_TRUE(r.ok) << r.error;
        ASSERT_TRUE(seen.insert(r.id).second);
        const ArchiveEntry& e = *by_id.at(r.id);
        EXPECT_EQ(r.bytes, d.node_bytes(e));
        EXPECT_EQ(archive_node_checksum(kArchiveVersion, r.bytes.data(), r.bytes.size()), e.checksum);
    }
}

}  // namespace

TEST(LocalFileSource, ReturnsTheExactBytesOfNodesRangesAndThePrefix) {
    const Dataset& d = dataset();
    LocalFileSource source(d.path);
    EXPECT_EQ(source.file_size(), d.bytes.size());
    expect_exact_nodes(source, d);
    std::vector<uint8_t> range = source.fetch_range(100, 1000);
    EXPECT_EQ(range, std::vector<uint8_t>(d.bytes.begin() + 100, d.bytes.begin() + 1100));
    EXPECT_THROW(source.fetch_range(d.bytes.size() - 10, 11), Error);
    DatasetPrefix prefix = load_prefix(source);
    EXPECT_EQ(prefix.entries.size(), d.file.index().entries().size());
    EXPECT_THROW(LocalFileSource("/nonexistent/file.cpq"), Error);
}

TEST(HttpSource, ServerRoutesAndRawRangesReturnTheExactBytesOverFewConnections) {
    const Dataset& d = dataset();
    test::TestHttpServer server(d.path, "sphere");
    server.start();
    for (bool raw : {false, true}) {
        SCOPED_TRACE(raw ? "raw .cpq with Range" : "server routes");
        HttpSettings settings;
        settings.parallel = 4;
        HttpSource source(raw ? server.file_url() : server.base_url(), settings);
        EXPECT_EQ(source.raw_mode(), raw);
        size_t before = server.connections();
        DatasetPrefix prefix = load_prefix(source);
        EXPECT_EQ(prefix.entries.size(), d.file.index().entries().size());
        expect_exact_nodes(source, d);
        // Persistent connections: hundreds of requests over at most `parallel` connections.
        EXPECT_LE(server.connections() - before, settings.parallel);
        EXPECT_LE(source.connections_opened(), settings.parallel);
        std::vector<uint8_t> range = source.fetch_range(96, 5000);
        EXPECT_EQ(range, std::vector<uint8_t>(d.bytes.begin() + 96, d.bytes.begin() + 5096));
    }
    // The prefix in raw mode: the first 64 KiB, then the rest of the index if longer.
    std::vector<std::string> targets = server.targets();
    EXPECT_TRUE(std::find(targets.begin(), targets.end(), "/api/datasets/sphere/prefix") != targets.end());
}

TEST(HttpSource, RawModeRefusesAWholeFileAnswerToAPartialRange) {
    const Dataset& d = dataset();
    ASSERT_GT(d.bytes.size(), kPrefixProbeBytes);
    test::TestHttpServer server(d.path, "sphere");
    server.ignore_ranges(true);
    server.start();
    HttpSource source(server.file_url());
    const ArchiveEntry& e = d.file.index().entries().back();
    try {
        source.fetch_node(e.key, e.offset, e.size);
        FAIL() << "a 200 answer to a partial range was accepted";
    } catch (const Error& err) {
        EXPECT_NE(std::string(err.what()).find("Range"), std::string::npos) << err.what();
    }
    EXPECT_THROW(load_prefix(source, 1), Error);

    // A file smaller than the prefix probe: the probe asked for the whole file, so a 200 with
    // the whole body is the right answer.
    std::string small = test::scratch_dir() + "/small.cpq";
    {
        ArchiveWriter writer(small, ArchiveKind::Catp);
        CatpMeta meta;
        std::vector<uint8_t> payload(300, 7);
        ArchiveEntry entry;
        entry.key = root_diamond().bits;
        entry.level = 0;
        writer.add_node(entry, payload.data(), payload.size());
        writer.finish(encode_catp_meta(meta));
    }
    test::TestHttpServer small_server(small, "small");
    small_server.ignore_ranges(true);
    small_server.start();
    HttpSource small_source(small_server.file_url());
    std::vector<uint8_t> prefix = fetch_prefix(small_source, 1);
    EXPECT_EQ(prefix, test::read_file(small));
}

TEST(HttpSource, NodeRouteErrorsAreReportedNotThrownAndUnknownNodesAreNotRetryable) {
    const Dataset& d = dataset();
    test::TestHttpServer server(d.path, "sphere");
    server.start();
    HttpSource source(server.base_url());
    SourceRequest r;
    r.id = 9;
    r.key = 12345;  // not a node
    r.size = 10;
    source.submit(r);
    std::vector<SourceResult> out;
    ASSERT_TRUE(eventually([&] {
        source.poll(out, 10);
        return !out.empty();
    }));
    EXPECT_FALSE(out[0].ok);
    EXPECT_FALSE(out[0].retryable);
    EXPECT_EQ(out[0].http_status, 404);
}

TEST(Fetcher, DeliversEveryRequestedNodeVerifiedAndDecoded) {
    const Dataset& d = dataset();
    Fetcher fetcher(std::make_unique<LocalFileSource>(d.path), decoding());
    std::vector<FetchRequest> wanted = d.all_requests();
    fetcher.request(wanted);
    std::vector<FetchedNode> got;
    ASSERT_TRUE(eventually([&] {
        fetcher.poll(got);
        return got.size() >= wanted.size();
    }));
    EXPECT_EQ(got.size(), wanted.size());
    std::set<uint64_t> keys;
    for (const FetchedNode& n : got) {
        ASSERT_TRUE(n.ok) << n.error;
        keys.insert(n.key);
        const ArchiveEntry& e = *d.file.index().find(DiamondId{n.key});
        EXPECT_EQ(*n.compressed, d.node_bytes(e));
        DiamondFragments ref = d.file.decode(e);
        ASSERT_TRUE(n.decoded);
        const DiamondFragments& fragments = catp_fragments(*n.decoded);
        EXPECT_EQ(fragments.slot_mask, ref.slot_mask);
        for (int s = 0; s < 8; ++s) EXPECT_EQ(fragments.slots[s].triangle_count(), ref.slots[s].triangle_count());
        EXPECT_EQ(d.h.node(n.node).key, n.key);
    }
    EXPECT_EQ(keys.size(), wanted.size());
    FetcherStats s = fetcher.stats();
    EXPECT_EQ(s.delivered, wanted.size());
    EXPECT_EQ(s.bytes_fetched, [&] {
        uint64_t b = 0;
        for (const FetchRequest& r : wanted) b += r.size;
        return b;
    }());
    EXPECT_TRUE(eventually([&] { return fetcher.idle(); }));
}

TEST(Fetcher, ErrorsCorruptBytesAndDroppedConnectionsAreRetriedUntilEveryNodeArrives) {
    const Dataset& d = dataset();
    for (bool raw : {false, true}) {
        SCOPED_TRACE(raw ? "raw" : "server");
        test::TestHttpServer server(d.path, "sphere");
        server.start();
        server.inject(60, {Fault::Status500, Fault::Corrupt, Fault::Close, Fault::Truncate, Fault::None});
        Fetcher fetcher(std::make_unique<HttpSource>(raw ? server.file_url() : server.base_url()), fast_retries());
        std::vector<FetchRequest> wanted = d.all_requests();
        std::set<uint64_t> pending;
        for (const FetchRequest& r : wanted) pending.insert(r.key);
        std::vector<FetchedNode> got;
        size_t failures_reported = 0;
        ASSERT_TRUE(eventually([&] {
            fetcher.request(wanted);  // every frame, as the client does
            got.clear();
            fetcher.poll(got);
            for (const FetchedNode& n : got) {
                if (!n.ok) {
                    failures_reported++;
                    continue;
                }
                const ArchiveEntry& e = *d.file.index().find(DiamondId{n.key});
                EXPECT_EQ(*n.compressed, d.node_bytes(e));
                pending.erase(n.key);
            }
            // Delivered nodes leave the wanted list, as the engine's requests do.
            wanted.erase(std::remove_if(wanted.begin(), wanted.end(), [&](const FetchRequest& r) { return !pending.count(r.key); }),
                         wanted.end());
            return pending.empty();
        }));
        FetcherStats s = fetcher.stats();
        EXPECT_GT(s.checksum_failures, 0u);
        EXPECT_GT(s.transport_errors, 0u);
        EXPECT_GT(s.retries, 0u);
        EXPECT_EQ(s.delivered, d.all_requests().size());
    }
}

TEST(Fetcher, SurvivesTheServerGoingAwayAndComingBack) {
    const Dataset& d = dataset();
    test::TestHttpServer server(d.path, "sphere");
    server.start();
    Fetcher fetcher(std::make_unique<HttpSource>(server.base_url()), fast_retries());
    std::vector<FetchRequest> all = d.all_requests();
    std::vector<FetchRequest> first(all.begin(), all.begin() + long(all.size() / 2));
    std::vector<FetchRequest> second(all.begin() + long(all.size() / 2), all.end());
    std::vector<FetchedNode> got;
    fetcher.request(first);
    ASSERT_TRUE(eventually([&] {
        fetcher.poll(got);
        return got.size() == first.size();
    }));
    server.stop();
    fetcher.request(second);
    // Connection refused: failures, backoff, reported failed, retried later.
    ASSERT_TRUE(eventually([&] { return fetcher.stats().transport_errors >= 5 && fetcher.stats().failed >= 1; }));
    server.start();  // same port
    std::set<uint64_t> pending;
    for (const FetchRequest& r : second) pending.insert(r.key);
    ASSERT_TRUE(eventually([&] {
        fetcher.request(second);
        got.clear();
        fetcher.poll(got);
        for (const FetchedNode& n : got)
            if (n.ok) pending.erase(n.key);
        return pending.empty();
    }));
    EXPECT_EQ(fetcher.stats().checksum_failures, 0u);
}

TEST(Fetcher, StaleRequestsAreCancelledBeforeTheyAreSent) {
    const Dataset& d = dataset();
    test::TestHttpServer server(d.path, "sphere");
    server.start();
    server.hold(true);
    HttpSettings http;
    http.parallel = 2;
    // One node per transfer, so that the two held transfers carry two nodes (coalesced transfers
    // are cancelled the same way: a node joins one only while it is queued).
    FetcherSettings settings = fast_retries();
    settings.coalesce_gap_bytes = -1;
    Fetcher fetcher(std::make_unique<HttpSource>(server.base_url(), http), settings);
    std::vector<FetchRequest> all = d.all_requests();
    ASSERT_GT(all.size(), 40u);
    fetcher.request(all);
    ASSERT_TRUE(eventually([&] { return server.waiting() == 2; }));  // two transfers at the gate
    std::vector<FetchRequest> keep(all.end() - 5, all.end());
    fetcher.request(keep);  // the camera turned: only these are still wanted
    ASSERT_TRUE(eventually([&] { return fetcher.stats().cancelled >= all.size() - 5 - 2; }));
    server.hold(false);
    std::vector<FetchedNode> got;
    ASSERT_TRUE(eventually([&] {
        fetcher.poll(got);
        return fetcher.idle();
    }));
    std::set<uint64_t> kept;
    for (const FetchRequest& r : keep) kept.insert(r.key);
    std::set<uint64_t> delivered;
    for (const FetchedNode& n : got) delivered.insert(n.key);
    for (uint64_t k : kept) EXPECT_TRUE(delivered.count(k));
    // At most the two transfers already running when the list changed were not kept.
    EXPECT_LE(delivered.size(), kept.size() + 2);
    size_t node_requests = 0;
    for (const std::string& t : server.targets()) node_requests += t.find("/nodes/") != std::string::npos;
    EXPECT_LE(node_requests, kept.size() + 2);
}

TEST(Fetcher, SuppliedBytesAreVerifiedAndDecodedWithoutAFetch) {
    const Dataset& d = dataset();
    test::TestHttpServer server(d.path, "sphere");
    server.start();
    Fetcher fetcher(std::make_unique<HttpSource>(server.base_url()), fast_retries());
    FetchRequest r = d.all_requests()[3];
    const ArchiveEntry& e = *d.file.index().find(DiamondId{r.key});
    fetcher.supply(r, std::make_shared<const std::vector<uint8_t>>(d.node_bytes(e)));
    std::vector<FetchedNode> got;
    ASSERT_TRUE(eventually([&] {
        fetcher.poll(got);
        return !got.empty();
    }));
    EXPECT_TRUE(got[0].ok);
    EXPECT_EQ(server.requests(), 0u);
    EXPECT_EQ(fetcher.stats().supplied, 1u);
    // Corrupt supplied bytes of a wanted node: fetched from the server instead.
    std::vector<uint8_t> bad = d.node_bytes(e);
    bad[bad.size() / 2] ^= 1;
    fetcher.request({r});
    fetcher.supply(r, std::make_shared<const std::vector<uint8_t>>(bad));
    got.clear();
    ASSERT_TRUE(eventually([&] {
        fetcher.poll(got);
        return !got.empty();
    }));
    EXPECT_TRUE(got[0].ok);
    EXPECT_EQ(*got[0].compressed, d.node_bytes(e));
}

TEST(HttpSource, APrefixLongerThanTheFirstProbeIsCompletedWithASecondRange) {
    // 3000 nodes and 100 KB of metadata that does not compress: a prefix longer than the 64 KiB
    // probe (the packed index alone would not be: 3000 nodes take about 25 KB).
    std::string path = test::scratch_dir() + "/big_index.cpq";
    {
        ArchiveWriter writer(path, ArchiveKind::Aqp);
        std::vector<uint8_t> payload(20, 1);
        for (uint64_t k = 0; k < 3000; ++k) {
            ArchiveEntry entry;
            entry.key = k;
            entry.level = uint16_t(k / 1000);
            payload[0] = uint8_t(k);
            writer.add_node(entry, payload.data(), payload.size());
        }
        std::vector<uint8_t> meta(100000);
        std::mt19937 rng(3);
        for (uint8_t& b : meta) b = uint8_t(rng());
        writer.finish(meta);
    }
    std::vector<uint8_t> file = test::read_file(path);
    ArchiveHeader header;
    ASSERT_EQ(parse_archive_header(file.data(), file.size(), header), "");
    uint64_t prefix_size = header.index_offset + header.index_size;
    ASSERT_GT(prefix_size, kPrefixProbeBytes);
    test::TestHttpServer server(path, "big");
    server.start();
    for (int mode = 0; mode < 3; ++mode) {
        std::unique_ptr<NodeSource> source;
        if (mode == 0) source = std::make_unique<LocalFileSource>(path);
        if (mode == 1) source = std::make_unique<HttpSource>(server.base_url());
        if (mode == 2) source = std::make_unique<HttpSource>(server.file_url());
        SCOPED_TRACE(source->describe());
        size_t before = server.requests();
        std::vector<uint8_t> prefix = fetch_prefix(*source, 1);
        ASSERT_GE(prefix.size(), prefix_size);
        EXPECT_TRUE(std::equal(prefix.begin(), prefix.end(), file.begin()));
        std::vector<ArchiveEntry> entries;
        EXPECT_EQ(parse_archive_index(header, prefix.data() + header.index_offset, header.index_size, entries), "");
        EXPECT_EQ(entries.size(), 3000u);
        size_t requests = server.requests() - before;
        if (mode == 1) {
            EXPECT_EQ(requests, 1u);  // the /prefix route: one request
        } else if (mode == 2) {
            EXPECT_EQ(requests, 2u);  // the probe, then the rest
        }
    }
}

// Parts fetched alone (the slot table's byte ranges) arrive decoded as their own slot only; parts
// queued together whose ranges are adjacent (a diamond's slots, 4 bytes apart) share transfers,
// over a local file and over HTTP ranges, and each gets exactly its bytes; without coalescing,
// one transfer per part.
TEST(Fetcher, PartsArriveAloneAndAdjacentOnesShareTransfers) {
    const Dataset& d = dataset();
    std::vector<FetchRequest> wanted;
    size_t nodes = 0;
    for (const HierarchyNode& n : d.h.nodes()) {
        if (!n.has_data || n.parts.size() < 2) continue;
        ASSERT_TRUE(n.fetch_parts);
        for (size_t i = 0; i < n.parts.size(); ++i) wanted.push_back(FetchRequest::of_part(n, i));
        if (++nodes == 6) break;
    }
    ASSERT_EQ(nodes, 6u);
    test::TestHttpServer server(d.path, "sphere");
    server.start();
    for (int mode = 0; mode < 3; ++mode) {
        FetcherSettings settings = decoding();
        if (mode == 2) settings.coalesce_gap_bytes = -1;
        std::unique_ptr<NodeSource> source;
        if (mode == 1) source = std::make_unique<HttpSource>(server.base_url());
        else source = std::make_unique<LocalFileSource>(d.path);
        Fetcher fetcher(std::move(source), settings);
        fetcher.request(wanted);
        std::vector<FetchedNode> got;
        ASSERT_TRUE(eventually([&] {
            fetcher.poll(got);
            return got.size() >= wanted.size();
        }));
        ASSERT_EQ(got.size(), wanted.size());
        std::set<uint64_t> ids;
        for (const FetchedNode& f : got) {
            ASSERT_TRUE(f.ok) << f.error;
            ASSERT_NE(f.part, kWholeNode);
            ids.insert(f.id);
            const HierarchyNode& n = d.h.node(f.node);
            const HierarchyPart& part = n.parts[f.part];
            EXPECT_EQ(*f.compressed, std::vector<uint8_t>(d.bytes.begin() + long(part.offset),
                                                          d.bytes.begin() + long(part.offset + part.size)));
            const DiamondFragments& fragments = catp_fragments(*f.decoded);
            EXPECT_EQ(fragments.slot_mask, 1u << part.id);
            DiamondFragments ref = d.file.decode(d.file.index().entries()[n.entry]);
            EXPECT_EQ(fragments.slots[part.id].indices, ref.slots[part.id].indices);
            EXPECT_EQ(f.decoded->part_primitives.at(f.part), ref.slots[part.id].triangle_count());
        }
        EXPECT_EQ(ids.size(), wanted.size());
        const FetcherStats s = fetcher.stats();
        if (mode == 2) EXPECT_EQ(s.transfers, wanted.size());
        else EXPECT_LE(s.transfers, nodes + 2) << "mode " << mode;  // about one per diamond
    }
}

namespace {

// A run of whole nodes that lie one after the other in the file (within `gap` bytes), in file
// order, with the byte range they span.
struct NodeRun {
    std::vector<FetchRequest> requests;
    uint64_t first = 0, end = 0;
};
NodeRun adjacent_nodes(const Dataset& d, size_t count, uint64_t gap = 0) {
    std::vector<FetchRequest> all = d.all_requests();
    std::sort(all.begin(), all.end(), [](const FetchRequest& a, const FetchRequest& b) { return a.offset < b.offset; });
    // Start in the middle of the file: neighbours on both sides that are not requested.
    for (size_t start = all.size() / 3; start + count <= all.size(); ++start) {
        NodeRun run;
        run.requests.push_back(all[start]);
        for (size_t i = start + 1; i < start + count; ++i) {
            const FetchRequest& prev = run.requests.back();
            if (all[i].size == 0 || all[i].offset < prev.offset + prev.size || all[i].offset - (prev.offset + prev.size) > gap)
                break;
            run.requests.push_back(all[i]);
        }
        if (run.requests.size() < count || run.requests.front().size == 0) continue;
        run.first = run.requests.front().offset;
        run.end = run.requests.back().offset + run.requests.back().size;
        return run;
    }
    ADD_FAILURE() << "no run of " << count << " adjacent nodes";
    return {};
}

// Requests `wanted` once and waits until every one was reported (ok or failed).
std::vector<FetchedNode> fetch_all(Fetcher& fetcher, const std::vector<FetchRequest>& wanted) {
    fetcher.request(wanted);
    std::vector<FetchedNode> got;
    EXPECT_TRUE(eventually([&] {
        fetcher.poll(got);
        return got.size() >= wanted.size() && fetcher.idle();
    }));
    return got;
}

}  // namespace

// Whole nodes queued together whose byte ranges touch go in one range transfer, from a local
// file, our server (its raw file route, not one /nodes/ request each) and a static server; each
// node gets exactly its bytes, checked against its own index checksum and decoded; the bytes and
// transfers counted are those of the one transfer. The priority order (here the reverse of the
// file order) does not split the run.
TEST(Fetcher, AdjacentWholeNodesQueuedTogetherArriveInOneTransferEachVerified) {
    const Dataset& d = dataset();
    const NodeRun run = adjacent_nodes(d, 8);
    ASSERT_EQ(run.requests.size(), 8u);
    std::vector<FetchRequest> wanted(run.requests.rbegin(), run.requests.rend());
    test::TestHttpServer server(d.path, "sphere");
    server.start();
    for (int mode = 0; mode < 3; ++mode) {
        SCOPED_TRACE(mode == 0 ? "local file" : mode == 1 ? "server" : "raw");
        std::unique_ptr<NodeSource> source;
        if (mode == 0) source = std::make_unique<LocalFileSource>(d.path);
        if (mode == 1) source = std::make_unique<HttpSource>(server.base_url());
        if (mode == 2) source = std::make_unique<HttpSource>(server.file_url());
        const size_t before = server.requests();
        Fetcher fetcher(std::move(source), decoding());
        std::vector<FetchedNode> got = fetch_all(fetcher, wanted);
        ASSERT_EQ(got.size(), wanted.size());
        std::set<uint64_t> keys;
        for (const FetchedNode& n : got) {
            ASSERT_TRUE(n.ok) << n.error;
            ASSERT_EQ(n.part, kWholeNode);
            keys.insert(n.key);
            const ArchiveEntry& e = *d.file.index().find(DiamondId{n.key});
            EXPECT_EQ(*n.compressed, d.node_bytes(e));
            ASSERT_TRUE(n.decoded);
            EXPECT_EQ(catp_fragments(*n.decoded).slot_mask, d.file.decode(e).slot_mask);
        }
        EXPECT_EQ(keys.size(), wanted.size());
        const FetcherStats s = fetcher.stats();
        EXPECT_EQ(s.transfers, 1u);
        EXPECT_EQ(s.bytes_fetched, run.end - run.first);
        EXPECT_EQ(s.delivered, wanted.size());
        EXPECT_EQ(s.checksum_failures, 0u);
        if (mode > 0) {
            EXPECT_EQ(server.requests() - before, 1u);
            EXPECT_EQ(server.targets().back(), "/files/sphere.cpq");
        }
    }
    // Without coalescing: one transfer (one /nodes/ request) per node.
    FetcherSettings off = decoding();
    off.coalesce_gap_bytes = -1;
    Fetcher fetcher(std::make_unique<HttpSource>(server.base_url()), off);
    const size_t before = server.requests();
    EXPECT_EQ(fetch_all(fetcher, wanted).size(), wanted.size());
    EXPECT_EQ(fetcher.stats().transfers, wanted.size());
    EXPECT_EQ(server.requests() - before, wanted.size());
}

// A node whose bytes in the file are bad, in a coalesced transfer: it alone fails its checksum,
// is retried in transfers of its own and reported failed; its neighbours in the same transfer
// arrive on the first attempt.
TEST(Fetcher, ACorruptNodeInACoalescedTransferFailsAloneAndItsNeighboursArrive) {
    const Dataset& d = dataset();
    const NodeRun run = adjacent_nodes(d, 5);
    ASSERT_EQ(run.requests.size(), 5u);
    const FetchRequest bad = run.requests[2];
    std::vector<uint8_t> bytes = d.bytes;
    bytes[bad.offset + bad.size / 2] ^= 0x5a;
    const std::string path = test::scratch_dir() + "/one_bad_node.cpq";
    {
        std::ofstream out(path, std::ios::binary);
        out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    }
    FetcherSettings settings = fast_retries();
    settings.failed_retry_delay = std::chrono::hours(1);  // reported failed once, not fetched again
    Fetcher fetcher(std::make_unique<LocalFileSource>(path), settings);
    std::vector<FetchedNode> got = fetch_all(fetcher, run.requests);
    ASSERT_EQ(got.size(), run.requests.size());
    for (const FetchedNode& n : got) {
        if (n.key == bad.key) {
            EXPECT_FALSE(n.ok);
            EXPECT_NE(n.error.find("checksum"), std::string::npos) << n.error;
            EXPECT_EQ(n.attempts, settings.max_attempts);
        } else {
            ASSERT_TRUE(n.ok) << n.error;
            EXPECT_EQ(n.attempts, 1u);
            EXPECT_EQ(*n.compressed, d.node_bytes(*d.file.index().find(DiamondId{n.key})));
        }
    }
    const FetcherStats s = fetcher.stats();
    EXPECT_EQ(s.checksum_failures, settings.max_attempts);
    EXPECT_EQ(s.failed, 1u);
    // The coalesced transfer, then the bad node's retries alone: its own bytes each time.
    EXPECT_EQ(s.transfers, settings.max_attempts);
    EXPECT_EQ(s.retries, settings.max_attempts - 1);
    EXPECT_EQ(s.bytes_fetched, (run.end - run.first) + uint64_t(settings.max_attempts - 1) * bad.size);
}

// Over HTTP (our server's raw file route and a static server): a coalesced answer corrupted on
// the wire fails only the node whose bytes were hit, fetched again alone (by key from our
// server); a coalesced answer cut short fails the transfer once, and every node it carried is
// retried alone and arrives.
TEST(Fetcher, OverHttpABadCoalescedAnswerIsRetriedNodeByNodeAndEveryNodeArrives) {
    const Dataset& d = dataset();
    const NodeRun run = adjacent_nodes(d, 5);
    ASSERT_EQ(run.requests.size(), 5u);
    // The test server corrupts the middle byte of the body: the node that holds it.
    const uint64_t middle = run.first + (run.end - run.first) / 2;
    uint64_t hit = 0;
    for (const FetchRequest& r : run.requests)
        if (r.offset <= middle && middle < r.offset + r.size) hit = r.key;
    test::TestHttpServer server(d.path, "sphere");
    server.start();
    for (bool raw : {false, true}) {
        for (Fault fault : {Fault::Corrupt, Fault::Truncate}) {
            SCOPED_TRACE(std::string(raw ? "raw" : "server") + (fault == Fault::Corrupt ? ", corrupt" : ", truncated"));
            Fetcher fetcher(std::make_unique<HttpSource>(raw ? server.file_url() : server.base_url()), fast_retries());
            const size_t before = server.targets().size();
            server.inject(1, {fault});
            std::vector<FetchedNode> got = fetch_all(fetcher, run.requests);
            ASSERT_EQ(got.size(), run.requests.size());
            for (const FetchedNode& n : got) {
                ASSERT_TRUE(n.ok) << n.error;
                EXPECT_EQ(*n.compressed, d.node_bytes(*d.file.index().find(DiamondId{n.key})));
                const bool retried = fault == Fault::Truncate || n.key == hit;
                EXPECT_EQ(n.attempts, retried ? 2u : 1u) << n.key;
            }
            const FetcherStats s = fetcher.stats();
            std::vector<std::string> targets = server.targets();
            targets.erase(targets.begin(), targets.begin() + long(before));
            if (fault == Fault::Corrupt) {
                EXPECT_EQ(s.checksum_failures, 1u);
                EXPECT_EQ(s.transport_errors, 0u);
                EXPECT_EQ(s.transfers, 2u);
                ASSERT_EQ(targets.size(), 2u);
                EXPECT_EQ(targets[1], raw ? "/files/sphere.cpq" : "/api/datasets/sphere/nodes/" + std::to_string(hit));
            } else {
                EXPECT_EQ(s.checksum_failures, 0u);
                EXPECT_EQ(s.transport_errors, 1u);
                EXPECT_EQ(s.transfers, 1 + run.requests.size());
                ASSERT_EQ(targets.size(), 1 + run.requests.size());
                for (size_t i = 1; i < targets.size() && !raw; ++i) {
                    EXPECT_NE(targets[i].find("/nodes/"), std::string::npos) << targets[i];
                }
            }
            EXPECT_EQ(targets[0], "/files/sphere.cpq");
            EXPECT_EQ(s.delivered, run.requests.size());
        }
    }
}

// Nodes queued together with a stretch of unrequested bytes between them share a transfer only
// when the stretch is within the gap; the gap's bytes are counted as fetched.
TEST(Fetcher, NodesFartherApartThanTheGapGetTransfersOfTheirOwn) {
    const Dataset& d = dataset();
    const NodeRun run = adjacent_nodes(d, 3);
    ASSERT_EQ(run.requests.size(), 3u);
    const std::vector<FetchRequest> ends = {run.requests[0], run.requests[2]};
    const uint64_t hole = run.requests[1].size;
    for (int64_t gap : {int64_t(hole) - 1, int64_t(hole)}) {
        FetcherSettings settings = decoding();
        settings.coalesce_gap_bytes = gap;
        Fetcher fetcher(std::make_unique<LocalFileSource>(d.path), settings);
        std::vector<FetchedNode> got = fetch_all(fetcher, ends);
        ASSERT_EQ(got.size(), 2u);
        for (const FetchedNode& n : got) EXPECT_TRUE(n.ok) << n.error;
        const FetcherStats s = fetcher.stats();
        const bool shared = uint64_t(gap) >= hole;
        EXPECT_EQ(s.transfers, shared ? 1u : 2u) << "gap " << gap;
        EXPECT_EQ(s.bytes_fetched, shared ? run.end - run.first : ends[0].size + ends[1].size);
    }
}

// Cancellation with coalescing on: nodes that would share a transfer, cancelled while queued
// (the camera turned before a connection was free), are never sent; the ones still wanted go
// together, and the bytes counted are theirs alone.
TEST(Fetcher, QueuedNeighboursCancelledBeforeTheirTransferStartsAreNeverFetched) {
    const Dataset& d = dataset();
    const NodeRun run = adjacent_nodes(d, 6);
    ASSERT_EQ(run.requests.size(), 6u);
    FetchRequest far;
    for (const FetchRequest& r : d.all_requests())
        if (r.size > 0 && (r.offset + r.size + 64 < run.first || r.offset > run.end + 64)) far = r;
    ASSERT_GT(far.size, 0u);
    test::TestHttpServer server(d.path, "sphere");
    server.start();
    server.hold(true);
    HttpSettings http;
    http.parallel = 1;
    Fetcher fetcher(std::make_unique<HttpSource>(server.base_url(), http), fast_retries());
    fetcher.request({far});
    ASSERT_TRUE(eventually([&] { return server.waiting() == 1; }));  // the only connection is busy
    std::vector<FetchRequest> all = {far};
    all.insert(all.end(), run.requests.begin(), run.requests.end());
    fetcher.request(all);
    ASSERT_TRUE(eventually([&] { return fetcher.stats().queued == run.requests.size(); }));
    fetcher.request({far, run.requests[0], run.requests[1]});
    ASSERT_TRUE(eventually([&] { return fetcher.stats().cancelled == run.requests.size() - 2; }));
    server.hold(false);
    std::vector<FetchedNode> got;
    ASSERT_TRUE(eventually([&] {
        fetcher.poll(got);
        return got.size() >= 3 && fetcher.idle();
    }));
    std::set<uint64_t> keys;
    for (const FetchedNode& n : got) {
        EXPECT_TRUE(n.ok) << n.error;
        keys.insert(n.key);
    }
    EXPECT_EQ(keys, (std::set<uint64_t>{far.key, run.requests[0].key, run.requests[1].key}));
    const FetcherStats s = fetcher.stats();
    EXPECT_EQ(s.transfers, 2u);
    EXPECT_EQ(s.bytes_fetched, uint64_t(far.size) + run.requests[0].size + run.requests[1].size);
    EXPECT_EQ(server.requests(), 2u);
}
