// Wavefront OBJ: geometry ("v", "f"), MeshLab-style vertex colours ("v x y z r g b") and normals
// ("vn"), per vertex or per face corner (averaged per vertex). Texture coordinates ("vt"),
// materials ("mtllib", "usemtl"), lines and points ("l", "p") and free-form geometry are left
// out and reported as dropped; groupings ("g", "o", "s") carry nothing a mesh holds.
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
    Mesh read(std::vector<std::string>& dropped);

private:
    bool next_statement(std::string_view& line);
    void vertex(Tokens& tokens);
    void normal(Tokens& tokens);
    void face(Tokens& tokens);
    uint32_t resolve(int64_t index, size_t count, const char* what);
    void parse_corner(std::string_view corner, uint32_t& vertex, bool& has_normal, uint32_t& normal);
    void finish_colors(Mesh& mesh) const;
    void finish_normals(Mesh& mesh);
    void report_dropped(std::vector<std::string>& dropped) const;

    InputFile file_;
    std::string joined_;  // a statement continued over several lines with '\'
    std::vector<Vec3d> positions_;
    std::vector<Vec3f> colors_;  // as written (0..1, or 0..255 in some exporters)
    std::vector<Vec3d> normals_;
    std::vector<uint32_t> indices_;
    bool normals_follow_vertices_ = true;  // every corner so far had vn index == v index
    float max_color_ = 0.0f;
    // Per-corner normals gathered per vertex: the sum of their unit vectors, how many corners
    // gave one, and the first vn index (to count vertices whose corners disagree).
    std::vector<Vec3d> normal_sums_;
    std::vector<uint32_t> normal_corners_, first_normal_;
    static constexpr uint32_t kCornersDisagree = UINT32_MAX - 1;  // in first_normal_
    size_t corners_with_normal_ = 0, corners_without_normal_ = 0;
    // Statements left out: texture coordinates, material statements, lines/points, other.
    size_t texcoords_ = 0, materials_ = 0, polylines_ = 0, freeform_ = 0;
    size_t texcoord_corners_ = 0;
    std::string material_library_;
    std::vector<std::string> notes_;  // what finish_normals did that the user should know
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
    if (n > 1 && !parts[1].empty()) {
        if (!parse_int(parts[1], index))
            file_.fail_line("malformed texture index in face corner %s", quoted(corner).c_str());
        texcoord_corners_++;
    }
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
        if (has_normal) {
            if (normal_sums_.size() <= vertex) {
                normal_sums_.resize(positions_.size(), Vec3d{0, 0, 0});
                normal_corners_.resize(positions_.size(), 0);
                first_normal_.resize(positions_.size(), UINT32_MAX);
            }
            const Vec3d& vn = normals_[normal];
            if (finite3(vn[0], vn[1], vn[2])) {
                Vec3f u = unit_normal(vn[0], vn[1], vn[2]);
                for (int k = 0; k < 3; ++k) normal_sums_[vertex][k] += u[k];
            }
            normal_corners_[vertex]++;
            uint32_t& first = first_normal_[vertex];
            if (first == UINT32_MAX) first = normal;
            else if (first != kCornersDisagree && first != normal && normals_[first] != vn) first = kCornersDisagree;
            corners_with_normal_++;
        } else {
            corners_without_normal_++;
        }
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

// "vn" entries used as they are when they are per vertex (one per vertex, and every face corner
// names normal i for vertex i). Per face corner (most exporters: "f v/vt/vn" with normals of
// their own numbering), each vertex gets the average of its corners' normals (a mesh holds one
// normal per vertex: where corners disagree, at hard edges, they are averaged); vertices no
// corner gives a normal get area-weighted ones. Both are reported.
void ObjReader::finish_normals(Mesh& mesh) {
    if (indices_.empty() || normals_.empty() || corners_with_normal_ == 0) return;
    if (normals_follow_vertices_ && normals_.size() == positions_.size()) {
        bool finite = true;
        for (const Vec3d& n : normals_) finite &= finite3(n[0], n[1], n[2]);
        if (finite) {
            mesh.normals.reserve(normals_.size());
            for (const Vec3d& n : normals_) mesh.normals.push_back(unit_normal(n[0], n[1], n[2]));
            return;
        }
    }
    normal_sums_.resize(positions_.size(), Vec3d{0, 0, 0});
    normal_corners_.resize(positions_.size(), 0);
    first_normal_.resize(positions_.size(), UINT32_MAX);
    size_t missing = 0, disagree = 0;
    std::vector<bool> used(positions_.size(), false);
    for (uint32_t i : indices_) used[i] = true;
    for (size_t v = 0; v < positions_.size(); ++v) {
        if (!used[v]) continue;
        missing += normal_corners_[v] == 0;
        disagree += first_normal_[v] == kCornersDisagree;
    }
    std::vector<Vec3f> computed;
    if (missing) {
        Mesh geometry;
        geometry.positions = positions_;
        geometry.indices = indices_;
        computed = compute_vertex_normals(geometry);
    }
    mesh.normals.resize(positions_.size());
    for (size_t v = 0; v < positions_.size(); ++v) {
        const Vec3d& sum = normal_sums_[v];
        mesh.normals[v] = normal_corners_[v] ? unit_normal(sum[0], sum[1], sum[2])
                          : computed.empty() ? Vec3f{0.0f, 0.0f, 1.0f}
                                             : computed[v];
    }
    if (disagree)
        notes_.push_back(strprintf("per-corner normals of %zu vertices that differ between faces (hard edges): "
                                   "averaged, one normal per vertex",
                                   disagree));
    if (missing)
        notes_.push_back(strprintf("normals for %zu vertices that no face corner gives one: computed from the faces",
                                   missing));
}

void ObjReader::report_dropped(std::vector<std::string>& dropped) const {
    if (texcoords_ || texcoord_corners_)
        dropped.push_back(strprintf("texture coordinates (%zu 'vt' statements, used by %zu face corners): not kept",
                                    texcoords_, texcoord_corners_));
    if (materials_)
        dropped.push_back(strprintf("materials (%zu 'mtllib'/'usemtl' statements%s): not kept; colours come from "
                                    "vertex colours only",
                                    materials_, material_library_.empty() ? "" : (", library " + material_library_).c_str()));
    if (polylines_) dropped.push_back(strprintf("%zu lines and points ('l', 'p'): not surface, not kept", polylines_));
    if (freeform_)
        dropped.push_back(strprintf("%zu free-form geometry statements (curves, surfaces): not kept", freeform_));
    if (!normals_.empty() && corners_with_normal_ == 0)
        dropped.push_back(strprintf("%zu 'vn' normals that no face uses: normals computed from the faces",
                                    normals_.size()));
    dropped.insert(dropped.end(), notes_.begin(), notes_.end());
}

Mesh ObjReader::read(std::vector<std::string>& dropped) {
    std::string_view line;
    while (next_statement(line)) {
        Tokens tokens(line);
        std::string_view keyword;
        if (!tokens.next(keyword)) continue;
        if (keyword == "v") vertex(tokens);
        else if (keyword == "vn") normal(tokens);
        else if (keyword == "f" || keyword == "fo") face(tokens);
        else if (keyword == "vt") texcoords_++;
        else if (keyword == "usemtl" || keyword == "mtllib") {
            materials_++;
            std::string_view library;
            if (keyword == "mtllib" && material_library_.empty() && tokens.next(library)) material_library_ = library;
        } else if (keyword == "l" || keyword == "p") polylines_++;
        else if (keyword == "vp" || keyword == "curv" || keyword == "curv2" || keyword == "surf" || keyword == "cstype")
            freeform_++;
        if (positions_.size() > UINT32_MAX) file_.fail_line("more vertices than 32-bit indices can address");
    }
    Mesh mesh;
    finish_colors(mesh);
    finish_normals(mesh);
    report_dropped(dropped);
    mesh.positions = std::move(positions_);
    mesh.indices = std::move(indices_);
    return mesh;
}

}  // namespace

Mesh read_obj(const std::string& path, std::vector<std::string>& dropped) {
    ObjReader reader(path);
    Mesh mesh = reader.read(dropped);
    return mesh;
}

}  // namespace catpaq::mesh_io
