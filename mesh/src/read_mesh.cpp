// read_mesh: format choice (extension, else content sniffing) and the checks every reader's
// output must pass before anyone else sees it.
#include <algorithm>
#include <string>
#include <string_view>

#include "base/error.h"
#include "input_file.h"
#include "mesh/io.h"
#include "readers.h"
#include "text_scan.h"

namespace catpaq {
namespace {

enum class Format { Unknown, Ply, Obj, Off, Stl };

Format format_from_extension(const std::string& path) {
    size_t dot = path.find_last_of("./");
    if (dot == std::string::npos || path[dot] != '.') return Format::Unknown;
    std::string extension = mesh_io::lowercase(std::string_view(path).substr(dot + 1));
    if (extension == "ply") return Format::Ply;
    if (extension == "obj") return Format::Obj;
    if (extension == "off") return Format::Off;
    if (extension == "stl") return Format::Stl;
    return Format::Unknown;
}

bool is_off_keyword(std::string_view token) {
    for (std::string_view prefix : {"ST", "C", "N"})
        if (token.substr(0, prefix.size()) == prefix) token.remove_prefix(prefix.size());
    return token == "OFF";
}

// The first statement of an OBJ file is almost always one of these.
bool is_obj_keyword(std::string_view token) {
    for (std::string_view keyword : {"v", "vn", "vt", "f", "o", "g", "s", "mtllib", "usemtl"})
        if (token == keyword) return true;
    return false;
}

// Looks at the first bytes: PLY and OFF have magic words, binary STL has a size that matches its
// triangle count, ascii STL starts with "solid", OBJ with one of its statements.
Format sniff(const std::string& path) {
    mesh_io::InputFile file(path);
    size_t head = size_t(std::min<uint64_t>(file.size(), 4096));
    if (!file.ensure(head)) return Format::Unknown;
    std::string_view start(file.data(), head);
    if (start.substr(0, 4) == "ply\n" || start.substr(0, 5) == "ply\r\n") return Format::Ply;
    if (file.size() >= 84) {
        const unsigned char* b = reinterpret_cast<const unsigned char*>(file.data() + 80);
        uint32_t triangles = uint32_t(b[0]) | uint32_t(b[1]) << 8 | uint32_t(b[2]) << 16 | uint32_t(b[3]) << 24;
        if (file.size() == 84 + 50 * uint64_t(triangles)) return Format::Stl;
    }
    // Skip comment lines, then classify by the first token.
    for (size_t pos = 0; pos < start.size();) {
        size_t end = start.find('\n', pos);
        size_t length = end == std::string_view::npos ? end : end - pos;
        std::string_view line = mesh_io::strip_comment(start.substr(pos, length));
        pos = end == std::string_view::npos ? start.size() : end + 1;
        std::string_view first;
        if (!mesh_io::Tokens(line).next(first)) continue;
        if (is_off_keyword(first)) return Format::Off;
        if (mesh_io::lowercase(first) == "solid") return Format::Stl;
        if (is_obj_keyword(first)) return Format::Obj;
        return Format::Unknown;
    }
    return Format::Unknown;
}

}  // namespace

Mesh read_mesh(const std::string& path, std::vector<std::string>* dropped) {
    Format format = format_from_extension(path);
    if (format == Format::Unknown) format = sniff(path);
    Mesh mesh;
    std::vector<std::string> ignored;
    switch (format) {
        case Format::Ply: mesh = mesh_io::read_ply(path, dropped ? *dropped : ignored); break;
        case Format::Obj: mesh = mesh_io::read_obj(path, dropped ? *dropped : ignored); break;
        case Format::Off: mesh = mesh_io::read_off(path); break;
        case Format::Stl: mesh = mesh_io::read_stl(path); break;
        case Format::Unknown: fail("'%s': unknown mesh format (expected PLY, OBJ, OFF or STL)", path.c_str());
    }
    validate_mesh(mesh, path);
    if (mesh.triangle_count() == 0) fail("'%s': empty mesh: the file has no triangles", path.c_str());
    return mesh;
}

}  // namespace catpaq
