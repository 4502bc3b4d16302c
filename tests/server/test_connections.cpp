// HTTP/1.1 connection handling: keep-alive, pipelining, HTTP/1.0, malformed requests, limits.
#include <random>

#include "support.h"

namespace catpaq::test {
namespace {

class Connections : public ServerTest {
protected:
    // After a bad request, the server must still answer on a fresh connection.
    static void expect_server_still_answers() {
        RawClient client(port());
        EXPECT_EQ(client.get("/api/datasets").status, 200);
    }
    // Sends raw bytes on a new connection and returns the response (then expects the close).
    static HttpResponse send_raw(const std::string& bytes, bool expect_close = true) {
        RawClient client(port());
        client.send(bytes);
        HttpResponse r;
        EXPECT_TRUE(client.read(r));
        if (expect_close) {
            EXPECT_TRUE(client.closed());
        }
        return r;
    }
};

TEST_F(Connections, KeepAliveServesSeveralRequestsOnOneConnection) {
    RawClient client(port());
    for (size_t i = 0; i < 12; ++i) {
        const BuiltNode& node = fixture->alpha[i];
        HttpResponse r = client.get(node_path("alpha", node.key));
        ASSERT_EQ(r.status, 200);
        EXPECT_FALSE(r.has("Connection"));  // HTTP/1.1: persistent by default
        EXPECT_EQ(r.body, to_string(node.bytes));
    }
    EXPECT_EQ(running->server->dataset_names().size(), 4u);
}

TEST_F(Connections, PipelinedRequestsAreAnsweredInOrderWithExactBodies) {
    RawClient client(port());
    std::string batch;
    std::vector<const BuiltNode*> expected;
    for (size_t i = 0; i < 10; ++i) {
        const BuiltNode& node = fixture->alpha[(i * 7) % fixture->alpha.size()];
        expected.push_back(&node);
        batch += request_text("GET", node_path("alpha", node.key));
    }
    client.send(batch);  // one write
    for (size_t i = 0; i < 10; ++i) {
        HttpResponse r;
        ASSERT_TRUE(client.read(r)) << i;
        EXPECT_EQ(r.status, 200);
        EXPECT_TRUE(r.body == to_string(expected[i]->bytes)) << "response " << i << " out of order or wrong";
    }
}

TEST_F(Connections, PipelinedMixOfHeadRangeErrorsAndTheTwoMegabyteNodeStaysFramed) {
    RawClient client(port());
    const std::string big = to_string(alpha_node(Fixture::kBigKey).bytes);
    const std::string file = read_whole_file(fixture->root() + "/alpha.cpq");
    client.send(request_text("GET", node_path("alpha", Fixture::kBigKey)) +
                request_text("HEAD", node_path("alpha", Fixture::kBigKey)) +
                request_text("GET", "/nope") + request_text("GET", "/files/alpha.cpq", "Range: bytes=5-9\r\n") +
                request_text("GET", node_path("alpha", Fixture::kEmptyKey)) +
                request_text("GET", node_path("alpha", Fixture::kBigKey)));
    HttpResponse r;
    ASSERT_TRUE(client.read(r));
    EXPECT_TRUE(r.body == big);
    ASSERT_TRUE(client.read(r, true));
    EXPECT_EQ(r.header("Content-Length"), std::to_string(big.size()));
    ASSERT_TRUE(client.read(r));
    EXPECT_EQ(r.status, 404);
    ASSERT_TRUE(client.read(r));
    EXPECT_EQ(r.status, 206);
    EXPECT_EQ(r.body, file.substr(5, 5));
    ASSERT_TRUE(client.read(r));
    EXPECT_EQ(r.status, 200);
    EXPECT_TRUE(r.body.empty());
    ASSERT_TRUE(client.read(r));
    EXPECT_TRUE(r.body == big);
}

TEST_F(Connections, ManyPipelinedRequestsBeyondOneWriteBatchAllArrive) {
    RawClient client(port());
    std::string batch;
    const size_t n = 150;  // more than the server queues per write
    for (size_t i = 0; i < n; ++i) batch += request_text("GET", node_path("alpha", fixture->alpha[i % 40].key));
    client.send(batch);
    for (size_t i = 0; i < n; ++i) {
        HttpResponse r;
        ASSERT_TRUE(client.read(r)) << i;
        ASSERT_TRUE(r.body == to_string(fixture->alpha[i % 40].bytes)) << i;
    }
}

TEST_F(Connections, ConnectionCloseAndHttp10WithoutKeepAliveCloseAfterTheResponse) {
    {
        RawClient client(port());
        client.send(request_text("GET", "/api/datasets", "Connection: close\r\n"));
        HttpResponse r;
        ASSERT_TRUE(client.read(r));
        EXPECT_EQ(r.status, 200);
        EXPECT_EQ(r.header("Connection"), "close");
        EXPECT_TRUE(client.closed());
    }
    {
        RawClient client(port());
        client.send("GET /api/datasets HTTP/1.0\r\n\r\n");  // no Host needed in 1.0
        HttpResponse r;
        ASSERT_TRUE(client.read(r));
        EXPECT_EQ(r.status, 200);
        EXPECT_TRUE(client.closed());
    }
    {
        RawClient client(port());
        client.send("GET /api/datasets HTTP/1.0\r\nConnection: keep-alive\r\n\r\n");
        HttpResponse r;
        ASSERT_TRUE(client.read(r));
        EXPECT_EQ(r.header("Connection"), "keep-alive");
        client.send("GET /api/datasets/alpha HTTP/1.0\r\nConnection: keep-alive\r\n\r\n");
        ASSERT_TRUE(client.read(r));
        EXPECT_EQ(r.status, 200);
    }
}

TEST_F(Connections, GarbageRequestLineGets400AndTheServerKeepsServing) {
    for (const std::string& garbage :
         {std::string("GARBAGE\r\n\r\n"), std::string("\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03\r\n\r\n", 15),
          std::string("GET  / HTTP/1.1\r\nHost: x\r\n\r\n"), std::string("GET / HTTP/1.1 extra\r\nHost: x\r\n\r\n"),
          std::string("GET /\r\n\r\n"), std::string("GET / HTTP/1.1\r\nNoColonHere\r\n\r\n"),
          std::string("GET / HTTP/1.1\r\nHost: x\r\n folded\r\n\r\n"),
          std::string("GET / HTTP/1.1\r\nBad Name: x\r\nHost: x\r\n\r\n"),
          std::string("GET /\x01 HTTP/1.1\r\nHost: x\r\n\r\n")}) {
        HttpResponse r = send_raw(garbage);
        EXPECT_EQ(r.status, 400) << garbage;
        EXPECT_EQ(r.header("Connection"), "close");
        expect_server_still_answers();
    }
}

TEST_F(Connections, BadMethodTokenGets400AndUnknownMethodGets405) {
    EXPECT_EQ(send_raw("G(T / HTTP/1.1\r\nHost: x\r\n\r\n").status, 400);
    RawClient client(port());
    HttpResponse r = client.request("FROBNICATE", "/api/datasets");
    EXPECT_EQ(r.status, 405);
    EXPECT_EQ(r.header("Allow"), "GET, HEAD, OPTIONS");
    EXPECT_EQ(client.get("/api/datasets").status, 200);
}

TEST_F(Connections, MissingHostDuplicateHostAndBadContentLengthGet400) {
    EXPECT_EQ(send_raw("GET /api/datasets HTTP/1.1\r\n\r\n").status, 400);
    EXPECT_EQ(send_raw("GET /api/datasets HTTP/1.1\r\nHost: a\r\nHost: b\r\n\r\n").status, 400);
    EXPECT_EQ(send_raw("GET /api/datasets HTTP/1.1\r\nHost: a\r\nContent-Length: 1x\r\n\r\n").status, 400);
    EXPECT_EQ(send_raw("GET /api/datasets HTTP/1.1\r\nHost: a\r\nContent-Length: 1\r\nContent-Length: 2\r\n\r\n")
                  .status,
              400);
    expect_server_still_answers();
}

TEST_F(Connections, UnsupportedVersionGets505AndChunkedBodyGets501) {
    EXPECT_EQ(send_raw("GET /api/datasets HTTP/2.0\r\nHost: x\r\n\r\n").status, 505);
    EXPECT_EQ(send_raw("POST /api/datasets HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n0\r\n\r\n").status,
              501);
    expect_server_still_answers();
}

TEST_F(Connections, HugeUrlGets414AndTheServerKeepsServing) {
    HttpResponse r = send_raw("GET /" + std::string(10000, 'a') + " HTTP/1.1\r\nHost: x\r\n\r\n");
    EXPECT_EQ(r.status, 414);
    // Without a line end at all.
    RawClient client(port());
    client.send("GET /" + std::string(20000, 'a'));
    HttpResponse r2;
    ASSERT_TRUE(client.read(r2));
    EXPECT_EQ(r2.status, 414);
    expect_server_still_answers();
}

TEST_F(Connections, HugeHeaderGets431AndTheServerKeepsServing) {
    HttpResponse one = send_raw("GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + std::string(20000, 'b') + "\r\n\r\n");
    EXPECT_EQ(one.status, 431);
    std::string many = "GET / HTTP/1.1\r\nHost: x\r\n";
    for (int i = 0; i < 150; ++i) many += "X-H" + std::to_string(i) + ": v\r\n";
    EXPECT_EQ(send_raw(many + "\r\n").status, 431);
    expect_server_still_answers();
}

TEST_F(Connections, OversizedRequestBodyGets413) {
    HttpResponse r = send_raw("POST / HTTP/1.1\r\nHost: x\r\nContent-Length: 100000000\r\n\r\n");
    EXPECT_EQ(r.status, 413);
    expect_server_still_answers();
}

TEST_F(Connections, RequestSplitIntoSingleBytesIsParsed) {
    RawClient client(port());
    const BuiltNode& node = fixture->alpha[2];
    std::string text = request_text("GET", node_path("alpha", node.key), "X-Test: 1\r\n");
    for (char c : text) client.send(std::string(1, c));
    HttpResponse r;
    ASSERT_TRUE(client.read(r));
    EXPECT_EQ(r.body, to_string(node.bytes));
}

TEST_F(Connections, RandomGarbageNeverStopsTheServer) {
    std::mt19937 rng{42};
    const std::string base = request_text("GET", "/files/alpha.cpq", "Range: bytes=0-9\r\n");
    for (int i = 0; i < 200; ++i) {
        std::string bytes;
        if (i % 2) {  // mutate a valid request
            bytes = base;
            for (int k = 0; k < 4; ++k) bytes[rng() % bytes.size()] = char(rng());
            bytes += "\r\n\r\n";  // keep the head complete: no waiting for the timeout
        } else {  // pure noise, sometimes with line ends
            bytes.resize(rng() % 600);
            for (char& c : bytes) c = char(rng() % 4 == 0 ? '\n' : rng());
            bytes += "\r\n\r\n";
        }
        RawClient client(port());
        client.send(bytes);
        HttpResponse r;
        while (client.read(r)) {  // whatever comes back is well-framed HTTP, until the close
            ASSERT_GE(r.status, 200) << i;
            ASSERT_LT(r.status, 600) << i;
            if (r.header("Connection") == "close") break;
            client.send(request_text("GET", "/nope", "Connection: close\r\n"));
        }
    }
    expect_server_still_answers();
}

TEST_F(Connections, BareLineFeedsAndLeadingEmptyLinesAreTolerated) {
    RawClient client(port());
    client.send("\r\nGET /api/datasets/alpha HTTP/1.1\nHost: x\n\n");
    HttpResponse r;
    ASSERT_TRUE(client.read(r));
    EXPECT_EQ(r.status, 200);
}

}  // namespace
}  // namespace catpaq::test
