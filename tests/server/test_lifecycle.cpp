// Many clients at once, slow clients, the connection limit, graceful stop, and a stock client.
#include <atomic>
#include <curl/curl.h>
#include <random>
#include <thread>

#include "support.h"

namespace catpaq::test {
namespace {

class Lifecycle : public ServerTest {};

TEST_F(Lifecycle, HundredConcurrentKeepAliveClientsAllGetExactBytes) {
    constexpr int kClients = 100, kRequests = 25;
    std::atomic<int> exact{0}, wrong{0}, failed{0};
    std::vector<std::thread> threads;
    for (int c = 0; c < kClients; ++c) {
        threads.emplace_back([&, c] {
            try {
                RawClient client(port());
                std::mt19937 rng{uint32_t(c)};
                for (int i = 0; i < kRequests; ++i) {
                    const BuiltNode& node = fixture->alpha[rng() % fixture->alpha.size()];
                    HttpResponse r = client.get(node_path("alpha", node.key));
                    (r.status == 200 && r.body == to_string(node.bytes) ? exact : wrong)++;
                }
            } catch (const std::exception&) {
                failed++;
            }
        });
    }
    for (std::thread& t : threads) t.join();
    EXPECT_EQ(failed.load(), 0);
    EXPECT_EQ(wrong.load(), 0);
    EXPECT_EQ(exact.load(), kClients * kRequests);
}

TEST(SlowClients, IncompleteRequestGets408AndIdleConnectionIsClosedAfterTheTimeout) {
    Fixture fixture;
    ServerSettings settings;
    settings.timeout_seconds = 0.2;
    RunningServer running(fixture.root(), settings);
    {
        RawClient slow(running.port);
        slow.send("GET /api/datasets HTTP/1.1\r\nHost: x\r\n");  // never finished
        HttpResponse r;
        ASSERT_TRUE(slow.read(r));
        EXPECT_EQ(r.status, 408);
        EXPECT_TRUE(slow.closed());
    }
    {
        RawClient idle(running.port);
        EXPECT_EQ(idle.get("/api/datasets").status, 200);
        EXPECT_TRUE(idle.closed());  // keep-alive connection left idle
    }
    RawClient fresh(running.port);
    EXPECT_EQ(fresh.get("/api/datasets").status, 200);
}

TEST(ConnectionLimit, ConnectionsBeyondTheLimitGet503AndTheOthersKeepWorking) {
    Fixture fixture;
    ServerSettings settings;
    settings.max_connections = 2;
    RunningServer running(fixture.root(), settings);
    auto a = std::make_unique<RawClient>(running.port);
    RawClient b(running.port);
    ASSERT_EQ(a->get("/api/datasets").status, 200);  // both are accepted and counted
    ASSERT_EQ(b.get("/api/datasets").status, 200);
    {
        RawClient c(running.port);  // the kernel accepts it; the server refuses it
        HttpResponse r;
        if (c.read(r)) {
            EXPECT_EQ(r.status, 503);
        }
        EXPECT_TRUE(c.closed());
    }
    EXPECT_EQ(a->get("/api/datasets/alpha").status, 200);
    EXPECT_EQ(b.get("/api/datasets/alpha").status, 200);
    EXPECT_TRUE(running.log.contains("refused a connection"));
    // Once one closes, a new client gets in (the server notices the close asynchronously).
    a.reset();
    bool served = false;
    for (int attempt = 0; attempt < 100 && !served; ++attempt) {
        RawClient d(running.port);
        HttpResponse r;
        d.send(request_text("GET", "/api/datasets"));
        served = d.read(r) && r.status == 200;
        if (!served) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    EXPECT_TRUE(served);
}

TEST(GracefulStop, InFlightResponseCompletesIdleConnectionsCloseAndNewConnectionsAreRefused) {
    Fixture fixture;
    RunningServer running(fixture.root());
    const std::string big = to_string(fixture.alpha[fixture.alpha.size() - 2].bytes);  // the 2 MiB node
    ASSERT_EQ(big.size(), size_t(2) << 20);
    RawClient idle(running.port);
    ASSERT_EQ(idle.get("/api/datasets").status, 200);
    RawClient busy(running.port, 8192);  // a small receive buffer keeps the server writing
    busy.send(request_text("GET", node_path("alpha", Fixture::kBigKey)));
    std::string first;
    ASSERT_TRUE(busy.read_raw(12, first));  // the response has started
    EXPECT_EQ(first, "HTTP/1.1 200");
    busy.unread(first);

    running.server->stop();
    HttpResponse rest;
    ASSERT_TRUE(busy.read(rest));  // reads the remaining head and the whole body
    EXPECT_TRUE(rest.body == big);
    EXPECT_TRUE(idle.closed());
    running.server->wait();
    EXPECT_THROW(RawClient refused(running.port), std::runtime_error);
}

TEST(GracefulStop, StopAndWaitFromAnotherThreadWhileWaitBlocks) {
    Fixture fixture;
    RunningServer running(fixture.root());
    std::thread waiter([&] { running.server->wait(); });
    RawClient client(running.port);
    EXPECT_EQ(client.get("/api/datasets").status, 200);
    running.server->stop();
    waiter.join();  // returns once stop() has drained the server
    running.server->stop();  // idempotent
    SUCCEED();
}

size_t collect(char* data, size_t size, size_t count, void* out) {
    static_cast<std::string*>(out)->append(data, size * count);
    return size * count;
}

TEST_F(Lifecycle, StockHttpClientFetchesRangesAndNodes) {
    CURL* curl = curl_easy_init();
    ASSERT_NE(curl, nullptr);
    std::string body;
    std::string base = "http://127.0.0.1:" + std::to_string(port());
    curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, collect);
    curl_easy_setopt(curl, CURLOPT_WRITEDATA, &body);
    curl_easy_setopt(curl, CURLOPT_ACCEPT_ENCODING, "");  // offer every encoding curl supports
    curl_easy_setopt(curl, CURLOPT_TIMEOUT, 10L);

    std::string file = read_whole_file(fixture->root() + "/alpha.cpq");
    std::string url = base + "/files/alpha.cpq";
    curl_easy_setopt(curl, CURLOPT_URL, url.c_str());
    curl_easy_setopt(curl, CURLOPT_RANGE, "96-1095");
    ASSERT_EQ(curl_easy_perform(curl), CURLE_OK);
    long status = 0;
    curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &status);
    EXPECT_EQ(status, 206);
    EXPECT_EQ(body, file.substr(96, 1000));

    const BuiltNode& node = fixture->alpha[11];
    body.clear();
    url = base + node_path("alpha", node.key);
    curl_easy_setopt(curl, CURLOPT_URL, url.c_str());
    curl_easy_setopt(curl, CURLOPT_RANGE, nullptr);
    ASSERT_EQ(curl_easy_perform(curl), CURLE_OK);  // reuses the connection
    curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &status);
    EXPECT_EQ(status, 200);
    EXPECT_EQ(body, to_string(node.bytes));
    curl_easy_cleanup(curl);
}

}  // namespace
}  // namespace catpaq::test
