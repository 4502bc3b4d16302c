// The same client code against `catpaq serve` (server/server.h, in-process, without any format's
// describer: it serves bytes): the node and prefix routes, and raw Range requests on /files/,
// give the exact bytes through the Fetcher.
#include <gtest/gtest.h>

#ifdef CATPAQ_HAVE_SERVER

#include <filesystem>
#include <set>

#include "catp/dataset.h"
#include "catp_client/catp_format.h"
#include "client/fetcher.h"
#include "client/hierarchy.h"
#include "server/server.h"
#include "test_core_support.h"

using namespace catpaq;

TEST(CatpaqServe, ServerRoutesAndRawRangesServeTheFetcherExactBytes) {
    namespace fs = std::filesystem;
    fs::path root = fs::path(test::scratch_dir()) / "serve_root";
    fs::create_directories(root / "scans");
    fs::copy_file(test::sphere_dataset(), root / "scans" / "sphere.cpq", fs::copy_options::overwrite_existing);
    ServerSettings settings;
    settings.root = root.string();
    settings.port = 0;
    settings.threads = 1;
    settings.log_level = LogLevel::Error;
    settings.log = [](LogLevel, std::string_view) {};
    StreamingServer server(settings);
    uint16_t port = server.start();
    std::string host = "http://127.0.0.1:" + std::to_string(port);

    CatpFile file(test::sphere_dataset());
    std::vector<uint8_t> bytes = test::read_file(test::sphere_dataset());
    Hierarchy h = build_catp_hierarchy(file.index());
    for (const std::string& url : {host + "/api/datasets/scans/sphere", host + "/files/scans/sphere.cpq"}) {
        SCOPED_TRACE(url);
        auto source = std::make_unique<HttpSource>(url);
        DatasetPrefix prefix = load_prefix(*source);
        ASSERT_EQ(prefix.entries.size(), file.index().entries().size());
        Fetcher fetcher(std::move(source));
        std::vector<FetchRequest> wanted;
        for (const HierarchyNode& n : h.nodes())
            if (n.has_data) wanted.push_back(FetchRequest::of(n));
        fetcher.request(wanted);
        std::vector<FetchedNode> got;
        auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
        while (got.size() < wanted.size() && std::chrono::steady_clock::now() < deadline) {
            fetcher.poll(got);
            std::this_thread::sleep_for(std::chrono::milliseconds(2));
        }
        ASSERT_EQ(got.size(), wanted.size());
        std::set<uint64_t> keys;
        for (const FetchedNode& n : got) {
            ASSERT_TRUE(n.ok) << n.error;
            const ArchiveEntry& e = *file.index().find(DiamondId{n.key});
            EXPECT_TRUE(std::equal(n.compressed->begin(), n.compressed->end(), bytes.begin() + long(e.offset)));
            keys.insert(n.key);
        }
        EXPECT_EQ(keys.size(), wanted.size());
        EXPECT_EQ(fetcher.stats().checksum_failures + fetcher.stats().transport_errors, 0u);
    }
    server.stop();
    server.wait();
}

#endif  // CATPAQ_HAVE_SERVER
