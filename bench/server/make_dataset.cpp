// server_bench_dataset OUT.cpq LIST.txt [--nodes N] [--min BYTES] [--max BYTES] [--seed S]
// Writes a CATP archive of N nodes with random payloads of uniformly random sizes in [min, max]
// over a few levels, and LIST.txt with one line per node: "key first_byte last_byte" (the node's
// byte range in the file, for Range requests against a static server).
#include <cstdio>
#include <random>
#include <vector>

#include "base/error.h"
#include "base/options.h"
#include "catp/format.h"
#include "common_codec/archive.h"

using namespace catpaq;

int main(int argc, char** argv) {
    try {
        Options options(argc, argv, "usage: server_bench_dataset OUT.cpq LIST.txt [--nodes N] [--min B] [--max B] [--seed S]\n");
        if (options.help()) {
            std::printf("%s", options.usage().c_str());
            return 0;
        }
        int64_t nodes = options.integer("nodes", 2000, 1, 10000000);
        int64_t min_size = options.integer("min", 4096, 1, 1 << 30);
        int64_t max_size = options.integer("max", 40960, min_size, 1 << 30);
        uint32_t seed = uint32_t(options.integer("seed", 1, 0, UINT32_MAX));
        options.finish();
        if (options.positional().size() != 2) {
            std::fprintf(stderr, "%s", options.usage().c_str());
            return 2;
        }
        const std::string out = options.positional()[0], list = options.positional()[1];
        std::mt19937_64 rng(seed);
        std::uniform_int_distribution<int64_t> size_dist(min_size, max_size);
        ArchiveWriter writer(out, ArchiveKind::Catp);
        std::vector<uint8_t> bytes;
        for (int64_t i = 0; i < nodes; ++i) {
            ArchiveEntry entry;
            entry.level = uint16_t(i < 8 ? 0 : i < 64 ? 1 : i < 512 ? 2 : 3);
            entry.key = (uint64_t(entry.level) << 58) | (rng() >> 8);  // large keys, like DiamondId bits
            entry.error = float(1.0 / (1 + entry.level));
            bytes.resize(size_t(size_dist(rng)));
            for (uint8_t& b : bytes) b = uint8_t(rng());
            entry.count = uint32_t(bytes.size() / 20);
            writer.add_node(entry, bytes.data(), bytes.size());
        }
        CatpMeta meta;
        for (int i = 0; i < 3; ++i) meta.bounds_max[i] = 1.0;
        meta.cell = 1.0 / (1 << 20);
        uint64_t size = writer.finish(encode_catp_meta(meta));

        ArchiveReader reader(out);
        FILE* f = std::fopen(list.c_str(), "w");
        if (!f) fail("cannot write '%s'", list.c_str());
        for (const ArchiveEntry& e : reader.entries())
            std::fprintf(f, "%llu %llu %llu\n", (unsigned long long)e.key, (unsigned long long)e.offset,
                         (unsigned long long)(e.offset + e.size - 1));
        std::fclose(f);
        std::printf("wrote %s: %lld nodes, %llu bytes\n", out.c_str(), (long long)nodes, (unsigned long long)size);
        return 0;
    } catch (const Error& e) {
        std::fprintf(stderr, "server_bench_dataset: %s\n", e.what());
        return 1;
    }
}
