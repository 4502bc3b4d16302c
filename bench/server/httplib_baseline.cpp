// server_bench_httplib --file DATASET.cpq [--port N] [--threads N]
// The node route of `catpaq serve` (GET /api/datasets/NAME/nodes/KEY, checksum-verified, ETag,
// immutable) on cpp-httplib, tuned as far as its API allows: a pre-routing handler instead of
// std::regex routes, a content provider that sends straight from the memory mapping, and a thread
// pool sized for the connections (each keep-alive connection occupies a pool thread). run.sh
// measures it next to `catpaq serve` and nginx: it is the baseline that decided the transport
// (server/src/server.cpp).
#include <httplib.h>

#include <cstdio>
#include <string>

#include "base/checksum.h"
#include "base/error.h"
#include "base/options.h"
#include "common_codec/archive.h"

using namespace catpaq;

int main(int argc, char** argv) {
    try {
        Options options(argc, argv, "usage: server_bench_httplib --file DATASET.cpq [--port N] [--threads N]\n");
        if (options.help()) {
            std::printf("%s", options.usage().c_str());
            return 0;
        }
        std::string file = options.require("file");
        int port = int(options.integer("port", 0, 0, 65535));
        size_t threads = size_t(options.integer("threads", 128, 1, 4096));
        options.finish();
        ArchiveReader reader(file);
        std::string name = file.substr(file.find_last_of('/') + 1);
        name = name.substr(0, name.size() - 4);
        const std::string prefix = "/api/datasets/" + name + "/nodes/";

        httplib::Server server;
        server.new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
        server.set_keep_alive_max_count(1u << 30);
        server.set_keep_alive_timeout(10);
        server.set_pre_routing_handler([&](const httplib::Request& req, httplib::Response& res) {
            if (req.path.compare(0, prefix.size(), prefix) != 0) {
                res.status = 404;
                return httplib::Server::HandlerResponse::Handled;
            }
            char* end = nullptr;
            uint64_t key = std::strtoull(req.path.c_str() + prefix.size(), &end, 10);
            int64_t index = *end == 0 ? reader.find(key) : -1;
            if (index < 0) {
                res.status = 404;
                return httplib::Server::HandlerResponse::Handled;
            }
            const ArchiveEntry& e = reader.entries()[size_t(index)];
            std::string error;
            const uint8_t* bytes = reader.node(size_t(index), &error);
            if (!bytes) {
                res.status = 500;
                return httplib::Server::HandlerResponse::Handled;
            }
            char etag[24];
            std::snprintf(etag, sizeof etag, "\"%016llx\"", (unsigned long long)e.checksum);
            res.set_header("ETag", etag);
            res.set_header("Cache-Control", "public, max-age=31536000, immutable");
            res.set_header("Access-Control-Allow-Origin", "*");
            res.set_content_provider(size_t(e.size), "application/octet-stream",
                                     [bytes](size_t offset, size_t length, httplib::DataSink& sink) {
                                         sink.write(reinterpret_cast<const char*>(bytes) + offset, length);
                                         return true;
                                     });
            return httplib::Server::HandlerResponse::Handled;
        });
        int bound = port ? (server.bind_to_port("127.0.0.1", port) ? port : -1) : server.bind_to_any_port("127.0.0.1");
        if (bound < 0) fail("cannot listen on port %d", port);
        std::printf("serving 1 datasets on http://127.0.0.1:%d/\n", bound);
        std::fflush(stdout);
        server.listen_after_bind();
        return 0;
    } catch (const Error& e) {
        std::fprintf(stderr, "server_bench_httplib: %s\n", e.what());
        return 1;
    }
}
