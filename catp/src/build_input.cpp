#include "build_input.h"

#include <algorithm>
#include <cctype>

#include "mesh/io.h"

namespace catpaq {

namespace {

class MeshInput final : public BuildInput {
public:
    MeshInput(const Mesh& mesh, std::string name) : mesh_(mesh), name_(std::move(name)) {}
    // Owns a mesh read from a file in a non-streamable format, and what its reader left out.
    MeshInput(Mesh&& owned, std::string name, std::vector<std::string> dropped)
        : owned_(std::move(owned)), mesh_(owned_), name_(std::move(name)), dropped_(std::move(dropped)) {}
    std::vector<std::string> dropped() const override { return dropped_; }

    std::string name() const override { return name_; }
    uint64_t vertex_count() const override { return mesh_.vertex_count(); }
    uint64_t triangle_estimate() override { return mesh_.triangle_count(); }
    bool has_normals() const override { return mesh_.has_normals(); }
    bool has_colors() const override { return mesh_.has_colors(); }

    size_t read_vertices(size_t max, std::vector<Vec3d>& positions, std::vector<Vec3f>* normals,
                         std::vector<Rgb8>* colors) override {
        size_t n = std::min<size_t>(max, mesh_.vertex_count() - next_vertex_);
        positions.insert(positions.end(), mesh_.positions.begin() + ptrdiff_t(next_vertex_),
                         mesh_.positions.begin() + ptrdiff_t(next_vertex_ + n));
        if (normals && mesh_.has_normals())
            normals->insert(normals->end(), mesh_.normals.begin() + ptrdiff_t(next_vertex_),
                            mesh_.normals.begin() + ptrdiff_t(next_vertex_ + n));
        if (colors && mesh_.has_colors())
            colors->insert(colors->end(), mesh_.colors.begin() + ptrdiff_t(next_vertex_),
                           mesh_.colors.begin() + ptrdiff_t(next_vertex_ + n));
        next_vertex_ += n;
        return n;
    }
    void rewind_triangles() override { next_triangle_ = 0; }
    size_t read_triangles(size_t max, std::vector<uint32_t>& indices) override {
        size_t n = std::min<size_t>(max, mesh_.triangle_count() - next_triangle_);
        indices.insert(indices.end(), mesh_.indices.begin() + ptrdiff_t(3 * next_triangle_),
                       mesh_.indices.begin() + ptrdiff_t(3 * (next_triangle_ + n)));
        next_triangle_ += n;
        return n;
    }
    void finish() override {}

private:
    Mesh owned_;
    const Mesh& mesh_;
    std::string name_;
    std::vector<std::string> dropped_;
    size_t next_vertex_ = 0, next_triangle_ = 0;
};

class PlyInput final : public BuildInput {
public:
    explicit PlyInput(std::string path) : path_(std::move(path)), stream_(std::make_unique<PlyStream>(path_)) {}

    std::string name() const override { return path_; }
    uint64_t vertex_count() const override { return stream_->vertex_count(); }
    uint64_t triangle_estimate() override {
        if (!peeked_) {
            // Read ahead; the first triangle pass serves these before reading on.
            peeked_ = true;
            uint64_t faces = stream_->read_faces(kPeekFaces, peek_);
            if (faces > 0) estimate_ = stream_->face_count() * (peek_.size() / 3) / faces;
        }
        return estimate_;
    }
    bool has_normals() const override { return stream_->has_normals(); }
    bool has_colors() const override { return stream_->has_colors(); }

    size_t read_vertices(size_t max, std::vector<Vec3d>& positions, std::vector<Vec3f>* normals,
                         std::vector<Rgb8>* colors) override {
        return stream_->read_vertices(max, positions, has_normals() ? normals : nullptr,
                                      has_colors() ? colors : nullptr);
    }
    void rewind_triangles() override {
        // The first pass continues from the vertices (and the peeked faces); later passes reopen
        // the file (PlyStream skips the unread vertices).
        triangle_estimate();
        if (passes_++ > 0) {
            stream_ = std::make_unique<PlyStream>(path_);
            peek_.clear();
        }
        peek_served_ = 0;
    }
    size_t read_triangles(size_t max, std::vector<uint32_t>& indices) override {
        if (peek_served_ < peek_.size() / 3) {
            size_t n = std::min(max, peek_.size() / 3 - peek_served_);
            indices.insert(indices.end(), peek_.begin() + ptrdiff_t(3 * peek_served_),
                           peek_.begin() + ptrdiff_t(3 * (peek_served_ + n)));
            peek_served_ += n;
            return n;
        }
        size_t before = indices.size();
        stream_->read_faces(max, indices);
        return (indices.size() - before) / 3;
    }
    void finish() override { stream_->finish(); }
    std::vector<std::string> dropped() const override { return stream_->dropped(); }

private:
    std::string path_;
    static constexpr size_t kPeekFaces = 4096;
    std::unique_ptr<PlyStream> stream_;
    int passes_ = 0;
    bool peeked_ = false;
    uint64_t estimate_ = 0;
    std::vector<uint32_t> peek_;  // indices of the first faces' triangles
    size_t peek_served_ = 0;      // triangles of peek_ returned in the current pass
};

bool is_ply(const std::string& path) {
    std::string ext = path.size() >= 4 ? path.substr(path.size() - 4) : "";
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return ext == ".ply";
}

}  // namespace

std::unique_ptr<BuildInput> mesh_build_input(const Mesh& mesh, std::string name) {
    return std::make_unique<MeshInput>(mesh, std::move(name));
}

std::unique_ptr<BuildInput> file_build_input(const std::string& path) {
    if (is_ply(path)) return std::make_unique<PlyInput>(path);
    std::vector<std::string> dropped;
    Mesh mesh = read_mesh(path, &dropped);
    return std::make_unique<MeshInput>(std::move(mesh), path, std::move(dropped));
}

}  // namespace catpaq
