// STL, binary and ascii. STL stores three unshared corners per triangle; corners with exactly
// the same position are welded into one vertex so the result is an indexed mesh (a closed STL
// model becomes a closed mesh). Facet normals and binary attribute bytes are ignored.
#include <algorithm>
#include <bit>
#include <cstring>
#include <string>
#include <string_view>

#include "base/error.h"
#include "input_file.h"
#include "readers.h"
#include "text_scan.h"

namespace catpaq::mesh_io {
namespace {

using ull = unsigned long long;

// Open-addressing hash from a position's bit pattern to its vertex index. -0.0 is folded into
// +0.0 first: they are the same point, and exporters emit both.
class Welder {
public:
    Welder(const InputFile& file, std::vector<Vec3d>& positions, size_t expected) : file_(file), positions_(positions) {
        size_t capacity = 1024;
        while (capacity < 2 * expected) capacity *= 2;
        slots_.assign(capacity, kEmpty);
    }

    uint32_t add(Vec3d p) {
        for (double& c : p) c += 0.0;  // -0.0 + 0.0 == +0.0 under round-to-nearest
        size_t mask = slots_.size() - 1;
        for (size_t slot = hash(p) & mask;; slot = (slot + 1) & mask) {
            uint32_t index = slots_[slot];
            if (index == kEmpty) break;
            if (same_bits(positions_[index], p)) return index;
        }
        if (positions_.size() >= UINT32_MAX) file_.fail("more distinct vertices than 32-bit indices can address");
        uint32_t index = uint32_t(positions_.size());
        positions_.push_back(p);
        if (2 * positions_.size() > slots_.size()) grow();
        else insert(index);
        return index;
    }

private:
    static constexpr uint32_t kEmpty = UINT32_MAX;

    static bool same_bits(const Vec3d& a, const Vec3d& b) {
        return std::memcmp(a.data(), b.data(), sizeof(Vec3d)) == 0;
    }

    static size_t hash(const Vec3d& p) {
        uint64_t h = 0x9e3779b97f4a7c15ull;
        for (double c : p) {
            h ^= std::bit_cast<uint64_t>(c);
            h *= 0xbf58476d1ce4e5b9ull;
            h ^= h >> 31;
        }
        return size_t(h);
    }

    void insert(uint32_t index) {
        size_t mask = slots_.size() - 1;
        size_t slot = hash(positions_[index]) & mask;
        while (slots_[slot] != kEmpty) slot = (slot + 1) & mask;
        slots_[slot] = index;
    }

    void grow() {
        slots_.assign(slots_.size() * 2, kEmpty);
        for (uint32_t i = 0; i < positions_.size(); ++i) insert(i);
    }

    const InputFile& file_;
    std::vector<Vec3d>& positions_;
    std::vector<uint32_t> slots_;
};

float load_f32_le(const char* p) {
    uint32_t bits;
    std::memcpy(&bits, p, 4);
    if constexpr (std::endian::native == std::endian::big)
        bits = (bits >> 24) | ((bits >> 8) & 0xff00) | ((bits << 8) & 0xff0000) | (bits << 24);
    return std::bit_cast<float>(bits);
}

uint32_t load_u32_le(const char* p) {
    const unsigned char* b = reinterpret_cast<const unsigned char*>(p);
    return uint32_t(b[0]) | uint32_t(b[1]) << 8 | uint32_t(b[2]) << 16 | uint32_t(b[3]) << 24;
}

Mesh read_binary(InputFile& file, uint32_t triangles) {
    Mesh mesh;
    Welder welder(file, mesh.positions, triangles / 2);
    reserve_huge(mesh.indices, size_t(triangles) * 3);
    file.consume(84);
    constexpr size_t kRecord = 50, kBatch = 20000;  // normal, 3 corners, 2 attribute bytes
    for (uint32_t first = 0; first < triangles;) {
        uint32_t n = std::min<uint32_t>(triangles - first, kBatch);
        if (!file.ensure(n * kRecord)) file.fail("truncated binary STL");  // the size was checked up front
        const char* p = file.data();
        for (uint32_t t = 0; t < n; ++t, p += kRecord) {
            for (int corner = 0; corner < 3; ++corner) {
                const char* c = p + 12 + 12 * corner;
                Vec3d position{load_f32_le(c), load_f32_le(c + 4), load_f32_le(c + 8)};
                if (!finite3(position[0], position[1], position[2]))
                    file.fail("triangle %u has a non-finite coordinate", first + t);
                mesh.indices.push_back(welder.add(position));
            }
        }
        file.consume(n * kRecord);
        first += n;
    }
    return mesh;
}

bool keyword_is(std::string_view token, std::string_view keyword) { return lowercase(token) == keyword; }

// Ascii STL: "solid name" { "facet normal n n n" "outer loop" {"vertex x y z"} "endloop"
// "endfacet" } "endsolid name", possibly several solids in one file.
class AsciiStl {
public:
    explicit AsciiStl(InputFile& file) : file_(file), welder_(file, mesh_.positions, file.size() / 256) {}

    Mesh read() {
        std::string_view keyword;
        Tokens tokens = next("solid", keyword);
        if (!keyword_is(keyword, "solid"))
            file_.fail_line("not an STL file: expected 'solid', found %s", quoted(keyword).c_str());
        for (;;) {
            tokens = next("'facet' or 'endsolid'", keyword);
            if (keyword_is(keyword, "facet")) {
                facet();
            } else if (keyword_is(keyword, "endsolid")) {
                std::string_view line;
                if (!next_line(line)) break;
                Tokens more(line);
                more.next(keyword);
                if (!keyword_is(keyword, "solid"))
                    file_.fail_line("expected 'solid' or the end of the file after 'endsolid', found %s",
                                    quoted(keyword).c_str());
            } else {
                file_.fail_line("expected 'facet' or 'endsolid', found %s", quoted(keyword).c_str());
            }
        }
        return std::move(mesh_);
    }

private:
    bool next_line(std::string_view& line) {
        while (file_.next_line(line))
            if (!Tokens(line).empty()) return true;
        return false;
    }

    // The next non-blank line's tokens, its first token in `keyword`; EOF means truncation.
    Tokens next(const char* expected, std::string_view& keyword) {
        std::string_view line;
        if (!next_line(line)) file_.fail("truncated: the file ends where %s was expected", expected);
        Tokens tokens(line);
        tokens.next(keyword);
        return tokens;
    }

    void expect(const char* expected) {
        std::string_view keyword;
        Tokens tokens = next(expected, keyword);
        std::string_view want(expected), second;
        size_t space = want.find(' ');
        if (!keyword_is(keyword, want.substr(0, space)) ||
            (space != std::string_view::npos && (!tokens.next(second) || !keyword_is(second, want.substr(space + 1)))))
            file_.fail_line("expected '%s', found %s", expected, quoted(keyword).c_str());
    }

    void facet() {
        expect("outer loop");
        std::string_view keyword;
        uint32_t first = 0, previous = 0;
        size_t corners = 0;
        for (;;) {
            Tokens tokens = next("'vertex' or 'endloop'", keyword);
            if (keyword_is(keyword, "endloop")) break;
            if (!keyword_is(keyword, "vertex"))
                file_.fail_line("expected 'vertex' or 'endloop', found %s", quoted(keyword).c_str());
            double v[3];
            std::string_view token;
            for (double& value : v)
                if (!tokens.next(token) || !parse_double(token, value))
                    file_.fail_line("malformed vertex: expected 'vertex x y z'");
            if (!tokens.empty()) file_.fail_line("malformed vertex: more than 3 coordinates");
            if (!finite3(v[0], v[1], v[2])) file_.fail_line("vertex has a non-finite coordinate");
            uint32_t index = welder_.add({v[0], v[1], v[2]});
            if (corners == 0) first = index;
            else if (corners >= 2) push_triangle(mesh_.indices, first, previous, index);
            previous = index;
            ++corners;
        }
        if (corners < 3) file_.fail_line("facet has %zu vertices (fewer than 3)", corners);
        expect("endfacet");
    }

    InputFile& file_;
    Mesh mesh_;
    Welder welder_;
};

// Binary STL is recognised by its size (84 + 50 * count), not by the "solid" prefix: many
// binary exporters start their 80-byte header with "solid".
Mesh read_stl_file(InputFile& file) {
    uint64_t size = file.size();
    bool starts_solid = false, has_control_bytes = false;
    size_t head = size_t(std::min<uint64_t>(size, 512));
    if (file.ensure(head)) {
        std::string_view start(file.data(), head);
        Tokens tokens(start);
        std::string_view first;
        starts_solid = tokens.next(first) && keyword_is(first.substr(0, 5), "solid");
        for (char c : start) has_control_bytes |= (unsigned char)c < 9;
    }
    if (size >= 84 && file.ensure(84)) {
        uint32_t triangles = load_u32_le(file.data() + 80);
        if (size == 84 + 50 * uint64_t(triangles)) return read_binary(file, triangles);
        // Binary content whose size disagrees with its count: cut short, or with junk appended.
        if (has_control_bytes)
            file.fail("truncated or malformed binary STL: the header declares %u triangles (%llu bytes) but the "
                      "file has %llu bytes",
                      triangles, ull(84 + 50 * uint64_t(triangles)), ull(size));
    }
    if (!starts_solid || has_control_bytes)
        file.fail("not an STL file: no 'solid' header, and the size does not match a binary triangle count");
    return AsciiStl(file).read();
}

}  // namespace

Mesh read_stl(const std::string& path) {
    InputFile file(path);
    return read_stl_file(file);
}

}  // namespace catpaq::mesh_io
