// Wavefront OBJ: geometry ("v", "f") plus MeshLab-style vertex colours ("v x y z r g b");
// every other statement (vt, g, o, s, usemtl, mtllib, l, p, ...) is ignored.
#include <algorithm>
#include <string>
#include <string_view>
#include <vector>

#include "base/error.h"
#include "input_file.h"
#include "readers.h"
#include "text_scan.h"

namespace catpaq::mesh_io {
namespace {

class ObjReader {
public:
    explicit ObjReader(const std::string& path) : file_(path) {}
    Mesh read();

private:
    bool next_statement(std::string_view& line);
    void vertex(Tokens& tokens);
    void normal(Tokens& tokens);
    void face(Tokens& tokens);
    uint32_t resolve(int64_t index, size_t count, const char* what);
    void parse_corner(std::string_view corner, uint32_t& vertex, bool& has_normal, uint32_t& normal);
    void finish_colors(Mesh& mesh) const;
    void finish_normals(Mesh& mesh) const;

    InputFile file_;
    std::string joined_;  // a statement continued over several lines with '\'
    std::vector<Vec3d> positions_;
    std::vector<Vec3f> colors_;  // as written (0..1, or 0..255 in some exporters)
    std::vector<Vec3d> normals_;
    std::vector<uint32_t> indices_;
    bool normals_follow_vertices_ = true;  // every corner so far had vn index == v index
    float max_color_ = 0.0f;
};

// The next line with continuations ('\' at the end) joined and the comment removed.
bool ObjReader::next_statement(std::string_view& line) {
    if (!file_.next_line(line)) return false;
    line = strip_comment(line);
    if (line.empty() || line.back() != '\\') return true;
    joined_.clear();
    for (;;) {
        line.remove_suffix(1);
        joined_.append(line);
        joined_ += ' ';
        if (!file_.next_line(line)) break;  // a final '\' continues into nothing
        line = strip_comment(line);
        if (line.empty() || line.back() != '\\') {
            joined_.append(line);
            break;
        }
    }
    line = joined_;
    return true;
}

void ObjReader::vertex(Tokens& tokens) {
    double v[8];
    int n = 0;
    std::string_view token;
    while (tokens.next(token)) {
        if (n == 8 || !parse_double(token, v[n]))
            file_.fail_line("expected a number in vertex %zu, found %s", positions_.size() + 1, quoted(token).c_str());
        ++n;
    }
    // 3: x y z; 4: x y z w (w ignored); 6: x y z r g b. Other counts have no agreed meaning.
    if (n != 3 && n != 4 && n != 6)
        file_.fail_line("vertex %zu has %d values (expected x y z, x y z w or x y z r g b)", positions_.size() + 1, n);
    if (!finite3(v[0], v[1], v[2]))
        file_.fail_line("vertex %zu has a non-finite coordinate", positions_.size() + 1);
    positions_.push_back({v[0], v[1], v[2]});
    if (n == 6) {
        if (!finite3(v[3], v[4], v[5])) file_.fail_line("vertex %zu has a non-finite colour", positions_.size());
        colors_.push_back({float(v[3]), float(v[4]), float(v[5])});
        for (int k = 3; k < 6; ++k) max_color_ = std::max(max_color_, float(v[k]));
    }
}

void ObjReader::normal(Tokens& tokens) {
    double v[3];
    std::string_view token;
    for (double& value : v) {
        if (!tokens.next(token) || !parse_double(token, value))
            file_.fail_line("malformed normal: expected 'vn x y z'");
    }
    normals_.push_back({v[0], v[1], v[2]});
}

// OBJ indices are 1-based; negative ones count back from the last element defined so far.
uint32_t ObjReader::resolve(int64_t index, size_t count, const char* what) {
    if (index == 0) file_.fail_line("%s index 0 is invalid (OBJ indices start at 1)", what);
    if (index < 0) {
        if (uint64_t(-index) > count)
            file_.fail_line("relative %s index %lld is out of range: it points before the first %s (%zu defined)",
                            what, (long long)index, what, count);
        return uint32_t(count - uint64_t(-index));
    }
    if (uint64_t(index) > count)
        file_.fail_line("%s index %lld is out of range (%zu defined so far)", what, (long long)index, count);
    return uint32_t(index - 1);
}

// One face corner: v, v/vt, v//vn or v/vt/vn.
void ObjReader::parse_corner(std::string_view corner, uint32_t& vertex, bool& has_normal, uint32_t& normal) {
    std::string_view parts[3];
    int n = 0;
    for (size_t start = 0;;) {
        size_t slash = corner.find('/', start);
        if (n == 3) file_.fail_line("malformed face corner %s", quoted(corner).c_str());
        parts[n++] = corner.substr(start, slash == std::string_view::npos ? slash : slash - start);
        if (slash == std::string_view::npos) break;
        start = slash + 1;
    }
    int64_t index;
    if (!parse_int(parts[0], index)) file_.fail_line("malformed face corner %s", quoted(corner).c_str());
    vertex = resolve(index, positions_.size(), "vertex");
    if (n > 1 && !parts[1].empty() && !parse_int(parts[1], index))
        file_.fail_line("malformed texture index in face corner %s", quoted(corner).c_str());
    has_normal = n == 3 && !parts[2].empty();
    if (has_normal) {
        if (!parse_int(parts[2], index))
            file_.fail_line("malformed normal index in face corner %s", quoted(corner).c_str());
        normal = resolve(index, normals_.size(), "normal");
    }
}

void ObjReader::face(Tokens& tokens) {
    std::string_view token;
    uint32_t first = 0, previous = 0;
    size_t corners = 0;
    while (tokens.next(token)) {
        uint32_t vertex, normal = 0;
        bool has_normal;
        parse_corner(token, vertex, has_normal, normal);
        if (!has_normal || normal != vertex) normals_follow_vertices_ = false;
        if (corners == 0) first = vertex;
        else if (corners >= 2) push_triangle(indices_, first, previous, vertex);
        previous = vertex;
        ++corners;
    }
    if (corners < 3) file_.fail_line("face has %zu vertices (fewer than 3)", corners);
}

// Colours are kept only if every vertex has one. MeshLab writes 0..1; a few exporters write
// 0..255, recognisable because some value exceeds 1.
void ObjReader::finish_colors(Mesh& mesh) const {
    if (colors_.empty() || colors_.size() != positions_.size()) return;
    double scale = max_color_ > 1.0f ? 1.0 / 255.0 : 1.0;
    mesh.colors.reserve(colors_.size());
    for (const Vec3f& c : colors_)
        mesh.colors.push_back({unit_to_byte(c[0] * scale), unit_to_byte(c[1] * scale), unit_to_byte(c[2] * scale)});
}

// "vn" entries become per-vertex normals only when they are unambiguous: one per vertex, and
// every face corner names normal i for vertex i. Otherwise they are per-corner data a vertex
// mesh cannot hold, and are dropped.
void ObjReader::finish_normals(Mesh& mesh) const {
    if (!normals_follow_vertices_ || indices_.empty() || normals_.size() != positions_.size()) return;
    for (const Vec3d& n : normals_)
        if (!finite3(n[0], n[1], n[2])) return;
    mesh.normals.reserve(normals_.size());
    for (const Vec3d& n : normals_) mesh.normals.push_back(unit_normal(n[0], n[1], n[2]));
}

Mesh ObjReader::read() {
    std::string_view line;
    while (next_statement(line)) {
        Tokens tokens(line);
        std::string_view keyword;
        if (!tokens.next(keyword)) continue;
        if (keyword == "v") vertex(tokens);
        else if (keyword == "vn") normal(tokens);
        else if (keyword == "f" || keyword == "fo") face(tokens);
        if (positions_.size() > UINT32_MAX) file_.fail_line("more vertices than 32-bit indices can address");
    }
    Mesh mesh;
    finish_colors(mesh);
    finish_normals(mesh);
    mesh.positions = std::move(positions_);
    mesh.indices = std::move(indices_);
    return mesh;
}

}  // namespace

Mesh read_obj(const std::string& path) { return ObjReader(path).read(); }

}  // namespace catpaq::mesh_io
