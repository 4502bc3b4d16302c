// write_ply: binary little-endian or ascii PLY through a 4 MB staging buffer into an AtomicFile.
// Ascii numbers use std::to_chars (shortest round-trip form), so ascii files read back exactly.
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "base/atomic_file.h"
#include "base/error.h"
#include "mesh/io.h"

namespace catpaq {
namespace {

constexpr size_t kFlushBytes = size_t(4) << 20;

// Appends values in PLY's binary little-endian layout or as ascii text, flushing to the file
// whenever the staging buffer is full.
class PlyOut {
public:
    explicit PlyOut(AtomicFile& file) : file_(file) { buffer_.reserve(kFlushBytes + 256); }

    void text(std::string_view s) { buffer_.insert(buffer_.end(), s.begin(), s.end()); }

    template <class T>
    void binary(T value) {
        char bytes[sizeof(T)];
        std::memcpy(bytes, &value, sizeof(T));
        if constexpr (std::endian::native == std::endian::big)
            for (size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(bytes[i], bytes[sizeof(T) - 1 - i]);
        buffer_.insert(buffer_.end(), bytes, bytes + sizeof(T));
    }

    template <class T>
    void number(T value, char separator) {
        char digits[64];
        auto result = std::to_chars(digits, digits + sizeof digits, value);
        buffer_.insert(buffer_.end(), digits, result.ptr);
        buffer_.push_back(separator);
    }

    // Called once per element instance: keeps the buffer bounded.
    void maybe_flush() {
        if (buffer_.size() >= kFlushBytes) flush();
    }
    void flush() {
        file_.write(buffer_.data(), buffer_.size());
        buffer_.clear();
    }

private:
    AtomicFile& file_;
    std::vector<char> buffer_;
};

// Double positions only where float would lose precision that matters: projected scan
// coordinates (around 1e6) need double; models near the origin are fine in float.
bool needs_double(const Mesh& mesh) {
    for (const Vec3d& p : mesh.positions)
        for (double c : p)
            if (std::fabs(c) > 1e5) return true;
    return false;
}

std::string header(const Mesh& mesh, bool binary, bool doubles) {
    std::string h = "ply\n";
    h += binary ? "format binary_little_endian 1.0\n" : "format ascii 1.0\n";
    h += "comment written by catpaq\n";
    h += "element vertex " + std::to_string(mesh.vertex_count()) + "\n";
    const char* type = doubles ? "double" : "float";
    for (const char* axis : {"x", "y", "z"}) h += strprintf("property %s %s\n", type, axis);
    if (mesh.has_normals()) h += "property float nx\nproperty float ny\nproperty float nz\n";
    if (mesh.has_colors()) h += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    h += "element face " + std::to_string(mesh.triangle_count()) + "\n";
    // "int" is what every reader accepts; "uint" only when the indices need the 32nd bit.
    h += mesh.vertex_count() > size_t(INT32_MAX) ? "property list uchar uint vertex_indices\n"
                                                  : "property list uchar int vertex_indices\n";
    h += "end_header\n";
    return h;
}

void write_binary_body(PlyOut& out, const Mesh& mesh, bool doubles) {
    for (size_t v = 0; v < mesh.vertex_count(); ++v) {
        for (double c : mesh.positions[v]) {
            if (doubles) out.binary(c);
            else out.binary(float(c));
        }
        if (mesh.has_normals())
            for (float c : mesh.normals[v]) out.binary(c);
        if (mesh.has_colors())
            for (uint8_t c : mesh.colors[v]) out.binary(c);
        out.maybe_flush();
    }
    for (size_t i = 0; i < mesh.indices.size(); i += 3) {
        out.binary(uint8_t(3));
        for (int k = 0; k < 3; ++k) out.binary(mesh.indices[i + k]);
        out.maybe_flush();
    }
}

void write_ascii_body(PlyOut& out, const Mesh& mesh, bool doubles) {
    for (size_t v = 0; v < mesh.vertex_count(); ++v) {
        bool more = mesh.has_normals() || mesh.has_colors();
        for (int k = 0; k < 3; ++k) {
            char separator = k < 2 || more ? ' ' : '\n';
            if (doubles) out.number(mesh.positions[v][k], separator);
            else out.number(float(mesh.positions[v][k]), separator);
        }
        if (mesh.has_normals())
            for (int k = 0; k < 3; ++k) out.number(mesh.normals[v][k], k < 2 || mesh.has_colors() ? ' ' : '\n');
        if (mesh.has_colors())
            for (int k = 0; k < 3; ++k) out.number(int(mesh.colors[v][k]), k < 2 ? ' ' : '\n');
        out.maybe_flush();
    }
    for (size_t i = 0; i < mesh.indices.size(); i += 3) {
        out.text("3 ");
        for (int k = 0; k < 3; ++k) out.number(mesh.indices[i + k], k < 2 ? ' ' : '\n');
        out.maybe_flush();
    }
}

}  // namespace

void write_ply(const std::string& path, const Mesh& mesh, bool binary) {
    validate_mesh(mesh, path);
    bool doubles = needs_double(mesh);
    AtomicFile file(path);
    PlyOut out(file);
    out.text(header(mesh, binary, doubles));
    if (binary) write_binary_body(out, mesh, doubles);
    else write_ascii_body(out, mesh, doubles);
    out.flush();
    file.commit();
}

}  // namespace catpaq
