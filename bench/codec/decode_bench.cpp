// decode_bench: fragment_decode on the real fragments of CATP archives, for A/B runs of decoder
// changes.
//
// Usage: decode_bench ARCHIVE.cpq... [--runs N] [--version V] [--compare-versions]
//
// Loads the encoded bytes of every fragment of each archive (split_diamond_node), then times fragment_decode over all of them into one reused FragmentMesh
// (best of N runs, CPU time of the thread: other processes on a shared machine only steal wall
// time). A digest (XXH3 of every decoded vertex and index buffer, chained) is printed per archive:
// two builds whose digests agree decoded the same bits, which is what decoder speed-ups must keep.
//
// --version V: every fragment is first decoded and re-encoded in bitstream version V (so that an
// archive converted by an older build measures the current decoder on the new format; the digest
// is that of the decoded arrays, so it equals the stored fragments' when V decodes to the same).
// --compare-versions: for every fragment, decoded from the archive, encodes it in the oldest and
// in the current bitstream version, decodes both and compares the decoded vertex and index arrays
// exactly (exit status 1 on any difference); prints the bytes of each version.
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

bool same_arrays(const FragmentMesh& a, const FragmentMesh& b) {
    if (!(a.layout == b.layout) || a.vertices.size() != b.vertices.size() || a.indices != b.indices) return false;
    for (size_t v = 0; v < a.vertices.size(); ++v)
        if (a.vertices[v].word0 != b.vertices[v].word0 || a.vertices[v].word1 != b.vertices[v].word1) return false;
    return true;
}

// --compare-versions (see the top of this file).
bool compare_versions(const std::string& input, const std::vector<std::vector<uint8_t>>& fragments) {
    FragmentMesh m, oldest, current;
    size_t bytes_oldest = 0, bytes_current = 0, bytes_stored = 0, differ = 0;
    std::vector<uint8_t> b_oldest, b_current;
    FragmentEncodeStats st, sum;
    for (const std::vector<uint8_t>& f : fragments) {
        if (fragment_decode(f.data(), f.size(), m) != FragmentStatus::Ok) fail("%s: cannot decode", input.c_str());
        b_oldest.clear();
        b_current.clear();
        bytes_stored += f.size();
        bytes_oldest += fragment_encode(m, b_oldest, nullptr, kFragmentOldestVersion);
        bytes_current += fragment_encode(m, b_current, &st, kFragmentVersion);
        sum.header_bytes += st.header_bytes;
        sum.connectivity_bytes += st.connectivity_bytes;
        sum.position_bytes += st.position_bytes;
        sum.normal_bytes += st.normal_bytes;
        sum.color_bytes += st.color_bytes;
        if (fragment_decode(b_oldest.data(), b_oldest.size(), oldest) != FragmentStatus::Ok ||
            fragment_decode(b_current.data(), b_current.size(), current) != FragmentStatus::Ok)
            fail("%s: a re-encoded fragment does not decode", input.c_str());
        differ += !same_arrays(oldest, current);
    }
    std::printf("%s: %zu fragments: stored %zu bytes, version %d %zu bytes, version %d %zu bytes (%+.3f%%); "
                "decoded arrays differ in %zu fragments\n",
                input.c_str(), fragments.size(), bytes_stored, kFragmentOldestVersion, bytes_oldest, kFragmentVersion,
                bytes_current, 100.0 * (double(bytes_current) / double(bytes_oldest) - 1.0), differ);
    std::printf("  version %d by part: header %zu, connectivity %zu, positions %zu, normals %zu, colours %zu bytes\n",
                kFragmentVersion, sum.header_bytes, sum.connectivity_bytes, sum.position_bytes, sum.normal_bytes,
                sum.color_bytes);
    return differ == 0;
}

}  // namespace

int main(int argc, char** argv) try {
    std::vector<std::string> inputs;
    int runs = 10;
    int version = 0;  // 0: as stored
    bool compare = false;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        if (a == "--runs" && i + 1 < argc)
            runs = std::atoi(argv[++i]);
        else if (a == "--version" && i + 1 < argc)
            version = std::atoi(argv[++i]);
        else if (a == "--compare-versions")
            compare = true;
        else if (a == "-h" || a == "--help") {
            std::printf("usage: decode_bench ARCHIVE.cpq... [--runs N] [--version V] [--compare-versions]\n");
            return 0;
        } else
            inputs.push_back(a);
    }
    if (inputs.empty()) fail("usage: decode_bench ARCHIVE.cpq... [--runs N] [--version V] [--compare-versions]");
    if (version != 0 && (version < kFragmentOldestVersion || version > kFragmentVersion))
        fail("--version: %d..%d", kFragmentOldestVersion, kFragmentVersion);
    for (const std::string& input : inputs) {
        std::vector<std::vector<uint8_t>> fragments = load_fragments(input);
        if (compare && !compare_versions(input, fragments)) return 1;
        if (version != 0) {
            FragmentMesh m;
            for (std::vector<uint8_t>& f : fragments) {
                if (fragment_decode(f.data(), f.size(), m) != FragmentStatus::Ok) fail("%s: cannot decode", input.c_str());
                f.clear();
                fragment_encode(m, f, nullptr, version);
            }
        }
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
