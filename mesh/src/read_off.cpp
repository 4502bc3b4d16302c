// Geomview OFF (ascii): "[C][N]OFF" header, counts (on the header line or the next), one vertex
// per line (x y z [nx ny nz] [r g b [a]]), one face per line (n i1 .. in [colour, ignored]).
// '#' starts a comment anywhere.
#include <algorithm>
#include <cmath>
#include <string>
#include <string_view>

#include "base/error.h"
#include "input_file.h"
#include "readers.h"
#include "text_scan.h"

namespace catpaq::mesh_io {
namespace {

using ull = unsigned long long;

struct OffHeader {
    bool colors = false, normals = false, texture = false;
    uint64_t vertices = 0, faces = 0;
};

class OffReader {
public:
    explicit OffReader(const std::string& path) : file_(path) {}
    Mesh read();

private:
    bool next_data_line(std::string_view& line);
    void parse_header();
    void parse_counts(Tokens& tokens);
    void vertex(std::string_view line, Mesh& mesh);
    void face(std::string_view line, Mesh& mesh);
    double number(Tokens& tokens, const char* what);

    InputFile file_;
    OffHeader header_;
};

// The next line that is not blank after removing its comment.
bool OffReader::next_data_line(std::string_view& line) {
    while (file_.next_line(line)) {
        line = strip_comment(line);
        if (!line.empty()) return true;
    }
    return false;
}

void OffReader::parse_header() {
    std::string_view line, keyword;
    if (!next_data_line(line)) file_.fail("not an OFF file: malformed header (the file is empty)");
    Tokens tokens(line);
    tokens.next(keyword);
    // Geomview prefixes: [ST][C][N][4][n]OFF. 4D and n-dimensional variants are not meshes we take.
    std::string_view rest = keyword;
    if (rest.substr(0, 2) == "ST") header_.texture = true, rest.remove_prefix(2);
    if (rest.substr(0, 1) == "C") header_.colors = true, rest.remove_prefix(1);
    if (rest.substr(0, 1) == "N") header_.normals = true, rest.remove_prefix(1);
    if (rest == "4OFF" || rest == "nOFF")
        file_.fail_line("%s files (4D or n-dimensional) are not supported", std::string(keyword).c_str());
    if (rest != "OFF")
        file_.fail_line("not an OFF file: malformed header (expected 'OFF', 'COFF' or 'NOFF', found %s)",
                        quoted(keyword).c_str());
    if (tokens.empty()) {
        if (!next_data_line(line)) file_.fail("malformed OFF header: the file ends before the vertex and face counts");
        tokens = Tokens(line);
    }
    std::string_view peek = tokens.rest();
    if (Tokens(peek).next(keyword) && keyword == "BINARY") file_.fail_line("binary OFF files are not supported");
    parse_counts(tokens);
}

void OffReader::parse_counts(Tokens& tokens) {
    int64_t counts[3] = {0, 0, 0};
    int n = 0;
    std::string_view token;
    while (tokens.next(token)) {
        if (n == 3 || !parse_int(token, counts[n]) || counts[n] < 0)
            file_.fail_line("malformed OFF header: expected 'vertices faces edges', found %s", quoted(token).c_str());
        ++n;
    }
    if (n < 2) file_.fail_line("malformed OFF header: expected 'vertices faces edges'");
    header_.vertices = uint64_t(counts[0]);
    header_.faces = uint64_t(counts[1]);
    if (header_.vertices > UINT32_MAX)
        file_.fail_line("%lld vertices exceed the 32-bit index limit", (long long)counts[0]);
    // Every vertex and face takes a line of at least 2 bytes: this bounds the counts by the file
    // size before anything is reserved. (Ordinary truncation gets a precise message later.)
    unsigned __int128 needed = ((unsigned __int128)header_.vertices + header_.faces) * 2;
    if (needed > (unsigned __int128)file_.remaining() + 1)
        file_.fail("truncated: the header declares %llu vertices and %llu faces, more than the %llu bytes that follow",
                   ull(header_.vertices), ull(header_.faces), ull(file_.remaining()));
}

double OffReader::number(Tokens& tokens, const char* what) {
    std::string_view token;
    double value;
    if (!tokens.next(token)) file_.fail_line("too few values: missing %s", what);
    if (!parse_double(token, value)) file_.fail_line("expected a number for %s, found %s", what, quoted(token).c_str());
    return value;
}

// Colour channels are floats in [0, 1] when written with a decimal point or exponent, else
// integers in [0, 255] (both conventions exist in the wild).
uint8_t color_channel(std::string_view token, double value) {
    if (token.find_first_of(".eE") != std::string_view::npos) return unit_to_byte(value);
    return uint8_t(std::clamp(value, 0.0, 255.0));
}

void OffReader::vertex(std::string_view line, Mesh& mesh) {
    Tokens tokens(line);
    size_t index = mesh.positions.size();
    double x = number(tokens, "x"), y = number(tokens, "y"), z = number(tokens, "z");
    if (!finite3(x, y, z)) file_.fail_line("vertex %zu has a non-finite coordinate", index);
    mesh.positions.push_back({x, y, z});
    if (header_.normals) {
        double nx = number(tokens, "nx"), ny = number(tokens, "ny"), nz = number(tokens, "nz");
        if (!finite3(nx, ny, nz)) file_.fail_line("vertex %zu has a non-finite normal", index);
        mesh.normals.push_back(unit_normal(nx, ny, nz));
    }
    if (header_.colors) {
        Rgb8 color;
        std::string_view token;
        for (int k = 0; k < 3; ++k) {
            double value;
            if (!tokens.next(token) || !parse_double(token, value) || !std::isfinite(value))
                file_.fail_line("vertex %zu: expected an r g b colour", index);
            color[k] = color_channel(token, value);
        }
        mesh.colors.push_back(color);
        if (!header_.texture && tokens.next(token) && !parse_double(token, x))  // optional alpha
            file_.fail_line("vertex %zu: malformed alpha %s", index, quoted(token).c_str());
    }
    if (header_.texture) {
        number(tokens, "s");
        number(tokens, "t");
    }
    if (!tokens.empty())
        file_.fail_line("vertex %zu has more values than the %s header declares", index,
                        header_.colors ? "COFF" : header_.normals ? "NOFF" : "OFF");
}

void OffReader::face(std::string_view line, Mesh& mesh) {
    Tokens tokens(line);
    std::string_view token;
    int64_t count;
    if (!tokens.next(token) || !parse_int(token, count))
        file_.fail_line("malformed face: expected a vertex count, found %s", quoted(token).c_str());
    if (count < 3) file_.fail_line("face has %lld vertices (fewer than 3)", (long long)count);
    uint32_t first = 0, previous = 0;
    for (int64_t corner = 0; corner < count; ++corner) {
        int64_t v;
        if (!tokens.next(token))
            file_.fail_line("face declares %lld vertices but lists %lld", (long long)count, (long long)corner);
        if (!parse_int(token, v)) file_.fail_line("malformed vertex index %s", quoted(token).c_str());
        if (v < 0 || uint64_t(v) >= header_.vertices)
            file_.fail_line("vertex index %lld is out of range (%llu vertices)", (long long)v, ull(header_.vertices));
        if (corner == 0) first = uint32_t(v);
        else if (corner >= 2) push_triangle(mesh.indices, first, previous, uint32_t(v));
        previous = uint32_t(v);
    }
    // A face colour may follow (a colour-map index, r g b or r g b a); it is ignored.
    int extra = 0;
    double ignored;
    while (tokens.next(token)) {
        if (++extra > 4 || !parse_double(token, ignored))
            file_.fail_line("unexpected values after the %lld face indices", (long long)count);
    }
}

Mesh OffReader::read() {
    parse_header();
    Mesh mesh;
    reserve_huge(mesh.positions, header_.vertices);
    reserve_huge(mesh.indices, header_.faces * 3);
    std::string_view line;
    for (uint64_t v = 0; v < header_.vertices; ++v) {
        if (!next_data_line(line))
            file_.fail("truncated: the file ends after %llu of %llu vertices", ull(v), ull(header_.vertices));
        vertex(line, mesh);
    }
    for (uint64_t f = 0; f < header_.faces; ++f) {
        if (!next_data_line(line))
            file_.fail("truncated: the file ends after %llu of %llu faces", ull(f), ull(header_.faces));
        face(line, mesh);
    }
    if (next_data_line(line))
        file_.fail_line("more data than the header declares (%llu vertices, %llu faces): counts do not match the data",
                        ull(header_.vertices), ull(header_.faces));
    return mesh;
}

}  // namespace

Mesh read_off(const std::string& path) { return OffReader(path).read(); }

}  // namespace catpaq::mesh_io
