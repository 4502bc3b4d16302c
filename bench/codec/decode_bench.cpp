// decode_bench: fragment_decode on the real fragments of CATP archives, for A/B runs of decoder
// changes.
//
// Usage: decode_bench ARCHIVE.cpq... [--runs N]
//
// Loads the encoded bytes of every fragment of each archive (split_diamond_node), then times fragment_decode over all of them into one reused FragmentMesh
// (best of N runs, CPU time of the thread: other processes on a shared machine only steal wall
// time). A digest (XXH3 of every decoded vertex and index buffer, chained) is printed per archive:
// two builds whose digests agree decoded the same bits, which is what decoder speed-ups must keep.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "base/checksum.h"
#include "base/error.h"
#include "base/sysinfo.h"
#include "catp/format.h"
#include "common_codec/archive.h"
#include "common_codec/fragment_codec.h"

using namespace catpaq;

namespace {

// The encoded bytes of every fragment of a CATP archive.
std::vector<std::vector<uint8_t>> load_fragments(const std::string& path) {
    ArchiveReader reader(path);
    std::vector<std::vector<uint8_t>> out;
    for (size_t e = 0; e < reader.entries().size(); ++e) {
        std::string error;
        const uint8_t* p = reader.node(e, &error);
        DiamondNodeSlots node;
        if (p) error = split_diamond_node(p, reader.entries()[e].size, node);
        if (!error.empty()) fail("%s: node %zu: %s", path.c_str(), e, error.c_str());
        for (int s = 0; s < 8; ++s)
            if (node.slot_mask & (1 << s)) out.emplace_back(node.fragment[s], node.fragment[s] + node.size[s]);
    }
    return out;
}

}  // namespace

int main(int argc, char** argv) try {
    std::vector<std::string> inputs;
    int runs = 10;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        if (a == "--runs" && i + 1 < argc)
            runs = std::atoi(argv[++i]);
        else if (a == "-h" || a == "--help") {
            std::printf("usage: decode_bench ARCHIVE.cpq... [--runs N]\n");
            return 0;
        } else
            inputs.push_back(a);
    }
    if (inputs.empty()) fail("usage: decode_bench ARCHIVE.cpq... [--runs N]");
    for (const std::string& input : inputs) {
        const std::vector<std::vector<uint8_t>> fragments = load_fragments(input);
        FragmentMesh out;
        size_t triangles = 0, vertices = 0, bytes = 0;
        uint64_t digest = 0;
        for (const std::vector<uint8_t>& f : fragments) {
            FragmentStatus st = fragment_decode(f.data(), f.size(), out);
            if (st != FragmentStatus::Ok) fail("%s: %s", input.c_str(), fragment_status_name(st));
            triangles += out.triangle_count();
            vertices += out.vertices.size();
            bytes += f.size();
            digest = digest * 31 + checksum64(out.vertices.data(), out.vertices.size() * sizeof(PackedVertex));
            digest = digest * 31 + checksum64(out.indices.data(), out.indices.size() * sizeof(uint32_t));
        }
        const double s = best_of(runs, [&] {
            for (const std::vector<uint8_t>& f : fragments)
                if (fragment_decode(f.data(), f.size(), out) != FragmentStatus::Ok) std::abort();
        }, thread_cpu_seconds);
        std::printf("%s: %zu fragments, %zu triangles, %zu vertices, %.2f bits/vertex\n", input.c_str(),
                    fragments.size(), triangles, vertices, 8.0 * double(bytes) / double(vertices));
        std::printf("  decode %8.2f ms  %6.2f Mtri/s  digest %016llx\n", s * 1e3, double(triangles) / s / 1e6,
                    (unsigned long long)digest);
    }
    return 0;
} catch (const std::exception& e) {
    std::fprintf(stderr, "decode_bench: %s\n", e.what());
    return 1;
}
