// PLY: the header parser and PlyStream, the one PLY body parser (read_mesh builds on it).
// Binary bodies are decoded with memcpy from a large buffer, with the byte order fixed per call
// by a template parameter, so the inner loops have no per-value virtual calls or iostreams.
#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cassert>
#include <cstring>
#include <limits>
#include <string_view>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "base/error.h"
#include "input_file.h"
#include "mesh/io.h"
#include "readers.h"
#include "text_scan.h"

namespace catpaq {
namespace {

using mesh_io::InputFile;
using mesh_io::Tokens;
using mesh_io::quoted;
using ull = unsigned long long;

constexpr size_t kNone = size_t(-1);
constexpr size_t kBatchBytes = size_t(1) << 20;  // bytes decoded per ensure() on the binary path
constexpr size_t kParallelVertices = 16384;       // batches of fixed-size vertices this large: on all cores

enum class PlyType : uint8_t { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };
enum class PlyFormat { Ascii, BinaryLittle, BinaryBig };

// The vertex properties the reader understands, in the order Impl::field stores them.
// kRadius is read only for point clouds (PlyStream::has_radii); a Mesh has no radii.
enum Field { kX, kY, kZ, kNx, kNy, kNz, kRed, kGreen, kBlue, kRadius, kFieldCount };

struct PlyProperty {
    std::string name;
    PlyType type = PlyType::Float32;  // the item type for lists
    bool list = false;
    PlyType count_type = PlyType::UInt8;
};

struct PlyElement {
    std::string name;
    uint64_t count = 0;
    std::vector<PlyProperty> properties;
    bool fixed_size = true;  // no list properties: every instance has `stride` bytes
    size_t stride = 0;
};

bool parse_type(std::string_view name, PlyType& type) {
    static const struct {
        const char* name;
        PlyType type;
    } kNames[] = {{"char", PlyType::Int8},     {"int8", PlyType::Int8},       {"uchar", PlyType::UInt8},
                  {"uint8", PlyType::UInt8},   {"short", PlyType::Int16},     {"int16", PlyType::Int16},
                  {"ushort", PlyType::UInt16}, {"uint16", PlyType::UInt16},   {"int", PlyType::Int32},
                  {"int32", PlyType::Int32},   {"uint", PlyType::UInt32},     {"uint32", PlyType::UInt32},
                  {"float", PlyType::Float32}, {"float32", PlyType::Float32}, {"double", PlyType::Float64},
                  {"float64", PlyType::Float64}};
    for (const auto& entry : kNames) {
        if (name == entry.name) {
            type = entry.type;
            return true;
        }
    }
    return false;
}

size_t type_size(PlyType type) {
    static const size_t kSizes[] = {1, 1, 2, 2, 4, 4, 4, 8};
    return kSizes[int(type)];
}

bool is_integer(PlyType type) { return type < PlyType::Float32; }

const char* type_name(PlyType type) {
    static const char* kNames[] = {"char", "uchar", "short", "ushort", "int", "uint", "float", "double"};
    return kNames[int(type)];
}

// Loads a T stored at p in file byte order (Swap: the file's order differs from the host's).
template <class T, bool Swap>
T load(const char* p) {
    T value;
    if constexpr (Swap) {
        char bytes[sizeof(T)];
        for (size_t i = 0; i < sizeof(T); ++i) bytes[i] = p[sizeof(T) - 1 - i];
        std::memcpy(&value, bytes, sizeof(T));
    } else {
        std::memcpy(&value, p, sizeof(T));
    }
    return value;
}

template <bool Swap>
double load_double(const char* p, PlyType type) {
    switch (type) {
        case PlyType::Int8: return load<int8_t, Swap>(p);
        case PlyType::UInt8: return load<uint8_t, Swap>(p);
        case PlyType::Int16: return load<int16_t, Swap>(p);
        case PlyType::UInt16: return load<uint16_t, Swap>(p);
        case PlyType::Int32: return load<int32_t, Swap>(p);
        case PlyType::UInt32: return load<uint32_t, Swap>(p);
        case PlyType::Float32: return load<float, Swap>(p);
        case PlyType::Float64: return load<double, Swap>(p);
    }
    return 0.0;
}

// Integer types only (the header parser rejects float counts and indices).
template <bool Swap>
int64_t load_int(const char* p, PlyType type) {
    switch (type) {
        case PlyType::Int8: return load<int8_t, Swap>(p);
        case PlyType::UInt8: return load<uint8_t, Swap>(p);
        case PlyType::Int16: return load<int16_t, Swap>(p);
        case PlyType::UInt16: return load<uint16_t, Swap>(p);
        case PlyType::Int32: return load<int32_t, Swap>(p);
        case PlyType::UInt32: return load<uint32_t, Swap>(p);
        default: assert(false && "float type used as an integer"); return 0;
    }
}

bool in_range(int64_t value, PlyType type) {
    switch (type) {
        case PlyType::Int8: return value >= -128 && value <= 127;
        case PlyType::UInt8: return value >= 0 && value <= 255;
        case PlyType::Int16: return value >= -32768 && value <= 32767;
        case PlyType::UInt16: return value >= 0 && value <= 65535;
        case PlyType::Int32: return value >= INT32_MIN && value <= INT32_MAX;
        case PlyType::UInt32: return value >= 0 && value <= int64_t(UINT32_MAX);
        default: return true;
    }
}

bool parse_u64(std::string_view token, uint64_t& out) {
    auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), out);
    return !token.empty() && error == std::errc() && end == token.data() + token.size();
}

}  // namespace

struct PlyStream::Impl {
    explicit Impl(const std::string& path) : file(path) {}

    InputFile file;
    PlyFormat format = PlyFormat::Ascii;
    std::vector<PlyElement> elements;
    size_t vertex_element = kNone, face_element = kNone;
    size_t field[kFieldCount];   // property index of each Field in the vertex element, or kNone
    size_t offset[kFieldCount];  // its byte offset in a fixed-size binary vertex
    PlyType field_type[kFieldCount];
    bool normals = false, colors = false, radii = false;
    size_t index_list = kNone;  // property index of vertex_indices in the face element
    size_t current = 0;         // element being read (file order)
    uint64_t done = 0;          // instances of `current` already consumed

    // --- header ---
    void parse_header();
    void parse_format(Tokens& tokens);
    void parse_element(Tokens& tokens);
    void parse_property(Tokens& tokens);
    void resolve_vertex_fields();
    void resolve_face_list();
    void compute_layouts();
    void check_declared_sizes();
    [[noreturn]] void header_error(const std::string& problem) const {
        file.fail_line("malformed PLY header: %s", problem.c_str());
    }

    // --- body ---
    bool ascii() const { return format == PlyFormat::Ascii; }
    bool swap() const { return (format == PlyFormat::BinaryBig) != (std::endian::native == std::endian::big); }
    [[noreturn]] void data_error(const std::string& problem) const {
        if (ascii()) file.fail_line("%s", problem.c_str());
        file.fail("%s", problem.c_str());
    }
    [[noreturn]] void truncated() const;
    void advance_to(size_t element);
    void skip_rest_of_current();
    void end_of_batch();

    void emit_vertex(const double* values, uint64_t index, std::vector<Vec3d>& positions,
                     std::vector<Vec3f>* normals_out, std::vector<Rgb8>* colors_out,
                     std::vector<float>* radii_out) const;
    void store_vertex(const double* values, uint64_t index, size_t at, std::vector<Vec3d>& positions,
                      std::vector<Vec3f>* normals_out, std::vector<Rgb8>* colors_out, std::vector<float>* radii_out) const;
    bool vertex_valid(const double* values, bool normals_wanted, bool colors_wanted, bool radii_wanted) const;
    template <bool Swap>
    bool parse_vertices_parallel(const char* data, size_t stride, size_t k, int last_field, std::vector<Vec3d>& positions,
                                 std::vector<Vec3f>* normals_out, std::vector<Rgb8>* colors_out,
                                 std::vector<float>* radii_out) const;
    uint8_t color_byte(double value, PlyType type, uint64_t index) const;
    void check_index(int64_t index, uint64_t face) const;

    template <bool Swap>
    void read_vertices_binary(size_t n, std::vector<Vec3d>& positions, std::vector<Vec3f>* normals_out,
                              std::vector<Rgb8>* colors_out, std::vector<float>* radii_out);
    template <bool Swap>
    void walk_binary_instance(const PlyElement& element, double* values);
    template <bool Swap>
    void read_faces_binary(size_t n, std::vector<uint32_t>& indices);
    template <bool Swap>
    size_t read_triangles_in_buffer(size_t max, std::vector<uint32_t>& indices);
    template <bool Swap>
    void read_face_binary(std::vector<uint32_t>& indices);
    template <bool Swap>
    void read_index_list_binary(const PlyProperty& list, uint64_t face, std::vector<uint32_t>& indices);

    std::string_view next_data_line();
    double ascii_value(Tokens& tokens, const PlyElement& element, PlyType type, const std::string& name) const;
    void read_vertices_ascii(size_t n, std::vector<Vec3d>& positions, std::vector<Vec3f>* normals_out,
                             std::vector<Rgb8>* colors_out, std::vector<float>* radii_out);
    void read_faces_ascii(size_t n, std::vector<uint32_t>& indices);
};

// ---------------------------------------------------------------------------------------------
// Header

void PlyStream::Impl::parse_header() {
    std::string_view line;
    if (!file.next_line(line) || mesh_io::strip_comment(line) != "ply")
        file.fail("not a PLY file: malformed header (the first line is not 'ply')");
    bool have_format = false;
    for (;;) {
        if (!file.next_line(line)) file.fail("malformed PLY header: the file ends before 'end_header'");
        Tokens tokens(line);
        std::string_view keyword;
        if (!tokens.next(keyword)) continue;
        if (keyword == "comment" || keyword == "obj_info") continue;
        if (keyword == "end_header") break;
        if (keyword == "format") {
            parse_format(tokens);
            have_format = true;
        } else if (keyword == "element") {
            parse_element(tokens);
        } else if (keyword == "property") {
            parse_property(tokens);
        } else {
            header_error("unknown keyword " + quoted(keyword));
        }
    }
    if (!have_format) header_error("no 'format' line");
    resolve_vertex_fields();
    resolve_face_list();
    compute_layouts();
    check_declared_sizes();
}

void PlyStream::Impl::parse_format(Tokens& tokens) {
    std::string_view name, version;
    if (!tokens.next(name) || !tokens.next(version) || !tokens.empty())
        header_error("expected 'format <ascii|binary_little_endian|binary_big_endian> 1.0'");
    if (name == "ascii") format = PlyFormat::Ascii;
    else if (name == "binary_little_endian") format = PlyFormat::BinaryLittle;
    else if (name == "binary_big_endian") format = PlyFormat::BinaryBig;
    else header_error("unknown format " + quoted(name));
    if (version.substr(0, 1) != "1") header_error("unsupported version " + quoted(version));
}

void PlyStream::Impl::parse_element(Tokens& tokens) {
    std::string_view name, count;
    PlyElement element;
    if (!tokens.next(name) || !tokens.next(count) || !tokens.empty())
        header_error("expected 'element <name> <count>'");
    if (!parse_u64(count, element.count)) header_error("bad element count " + quoted(count));
    element.name = std::string(name);
    elements.push_back(std::move(element));
}

void PlyStream::Impl::parse_property(Tokens& tokens) {
    if (elements.empty()) header_error("'property' before any 'element'");
    PlyProperty property;
    std::string_view type, name;
    if (!tokens.next(type)) header_error("expected 'property <type> <name>'");
    if (type == "list") {
        std::string_view count_type;
        property.list = true;
        if (!tokens.next(count_type) || !tokens.next(type))
            header_error("expected 'property list <count type> <item type> <name>'");
        if (!parse_type(count_type, property.count_type)) header_error("unknown type " + quoted(count_type));
        if (!is_integer(property.count_type)) header_error("list count type must be an integer type");
    }
    if (!parse_type(type, property.type)) header_error("unknown type " + quoted(type));
    if (!tokens.next(name) || !tokens.empty()) header_error("expected a property name after the type");
    property.name = std::string(name);
    elements.back().properties.push_back(std::move(property));
}

void PlyStream::Impl::resolve_vertex_fields() {
    for (size_t e = 0; e < elements.size(); ++e) {
        if (elements[e].name == "vertex" && vertex_element == kNone) vertex_element = e;
        if (elements[e].name == "face" && face_element == kNone) face_element = e;
    }
    if (vertex_element == kNone) header_error("no 'vertex' element");
    if (face_element != kNone && face_element < vertex_element)
        header_error("the face element comes before the vertex element (not supported)");

    const PlyElement& vertex = elements[vertex_element];
    // Accepted spellings per Field; the first found wins.
    static const std::vector<std::vector<std::string_view>> kNames = {
        {"x"}, {"y"}, {"z"}, {"nx"}, {"ny"}, {"nz"},
        {"red", "diffuse_red", "r"}, {"green", "diffuse_green", "g"}, {"blue", "diffuse_blue", "b"},
        {"radius", "scale"}};
    for (int f = 0; f < kFieldCount; ++f) {
        field[f] = kNone;
        for (std::string_view name : kNames[f]) {
            for (size_t p = 0; p < vertex.properties.size() && field[f] == kNone; ++p)
                // A radius list is some other data: skipped as before radii were read.
                if (vertex.properties[p].name == name && !(f == kRadius && vertex.properties[p].list)) field[f] = p;
        }
        if (field[f] != kNone) {
            if (vertex.properties[field[f]].list)
                header_error("vertex property '" + vertex.properties[field[f]].name + "' is a list");
            field_type[f] = vertex.properties[field[f]].type;
        }
    }
    for (int f : {kX, kY, kZ})
        if (field[f] == kNone) header_error(std::string("the vertex element has no '") + "xyz"[f] + "' property");
    normals = field[kNx] != kNone && field[kNy] != kNone && field[kNz] != kNone;
    colors = field[kRed] != kNone && field[kGreen] != kNone && field[kBlue] != kNone;
    radii = field[kRadius] != kNone;
    if (vertex.count > UINT32_MAX)
        header_error(strprintf("%llu vertices exceed the 32-bit index limit", ull(vertex.count)));
}

void PlyStream::Impl::resolve_face_list() {
    if (face_element == kNone) return;
    const PlyElement& face = elements[face_element];
    for (size_t p = 0; p < face.properties.size() && index_list == kNone; ++p)
        if (face.properties[p].name == "vertex_indices" || face.properties[p].name == "vertex_index") index_list = p;
    if (index_list == kNone) header_error("the face element has no 'vertex_indices' list");
    const PlyProperty& list = face.properties[index_list];
    if (!list.list) header_error("face property 'vertex_indices' is not a list");
    if (!is_integer(list.type))
        header_error(std::string("face indices have non-integer type ") + type_name(list.type));
}

void PlyStream::Impl::compute_layouts() {
    for (PlyElement& element : elements) {
        element.stride = 0;
        for (const PlyProperty& property : element.properties) {
            if (property.list) element.fixed_size = false;
            element.stride += type_size(property.list ? property.count_type : property.type);
        }
    }
    const PlyElement& vertex = elements[vertex_element];
    for (int f = 0; f < kFieldCount; ++f) {
        if (field[f] == kNone) continue;
        offset[f] = 0;
        for (size_t p = 0; p < field[f]; ++p) offset[f] += type_size(vertex.properties[p].type);
    }
}

// Rejects headers whose counts cannot fit in the file, before anyone reserves memory for them:
// each binary instance takes at least `stride` bytes (lists at least their count), each ascii
// instance at least one character and a line break. (A precise message for an ordinary
// truncation comes from the body reader, which knows where the data stops.)
void PlyStream::Impl::check_declared_sizes() {
    unsigned __int128 needed = 0;
    for (const PlyElement& element : elements) {
        uint64_t per_instance = ascii() ? (element.properties.empty() ? 0 : 2) : element.stride;
        needed += (unsigned __int128)element.count * per_instance;
    }
    if (ascii() && needed > 0) needed -= 1;  // the last line needs no line break
    if (needed > file.remaining()) {
        std::string counts;
        for (const PlyElement& element : elements)
            counts += strprintf("%s%llu %s", counts.empty() ? "" : ", ", ull(element.count), element.name.c_str());
        file.fail("truncated: the header declares %s, which needs more than the %llu bytes that follow it",
                  counts.c_str(), ull(file.remaining()));
    }
}

// ---------------------------------------------------------------------------------------------
// Body: element bookkeeping

void PlyStream::Impl::truncated() const {
    const PlyElement& element = elements[current];
    file.fail("truncated: the file ends in %s %llu of %llu", element.name.c_str(), ull(done), ull(element.count));
}

void PlyStream::Impl::end_of_batch() {
    if (done == elements[current].count) {
        ++current;
        done = 0;
    }
}

void PlyStream::Impl::advance_to(size_t element) {
    while (current < element) skip_rest_of_current();
}

void PlyStream::Impl::skip_rest_of_current() {
    const PlyElement& element = elements[current];
    uint64_t left = element.count - done;
    if (ascii()) {
        for (uint64_t i = 0; i < left; ++i) {
            next_data_line();
            ++done;
        }
    } else if (element.fixed_size) {
        // check_declared_sizes() bounded count * stride by the file size: no overflow here.
        uint64_t bytes = left * element.stride, skipped = file.skip(bytes);
        if (skipped < bytes) {
            done += skipped / std::max<size_t>(element.stride, 1);
            truncated();
        }
    } else {
        for (uint64_t i = 0; i < left; ++i) {
            if (swap()) walk_binary_instance<true>(element, nullptr);
            else walk_binary_instance<false>(element, nullptr);
            ++done;
        }
    }
    ++current;
    done = 0;
}

// ---------------------------------------------------------------------------------------------
// Body: values shared by both encodings

uint8_t PlyStream::Impl::color_byte(double value, PlyType type, uint64_t index) const {
    switch (type) {
        case PlyType::UInt8: return uint8_t(value);
        case PlyType::UInt16: return uint8_t((value + 128.0) / 257.0);  // 0..65535 -> 0..255
        case PlyType::Float32:
        case PlyType::Float64:
            if (!std::isfinite(value)) data_error(strprintf("vertex %llu has a non-finite colour", ull(index)));
            return mesh_io::unit_to_byte(value);
        default: return uint8_t(std::clamp(value, 0.0, 255.0));
    }
}

// Writes vertex `index`'s values to element `at` of the outputs (the colour's conversion throws,
// naming `index`, on a non-finite float colour).
void PlyStream::Impl::store_vertex(const double* values, uint64_t index, size_t at, std::vector<Vec3d>& positions,
                                   std::vector<Vec3f>* normals_out, std::vector<Rgb8>* colors_out,
                                   std::vector<float>* radii_out) const {
    positions[at] = {values[kX], values[kY], values[kZ]};
    if (normals_out) (*normals_out)[at] = mesh_io::unit_normal(values[kNx], values[kNy], values[kNz]);
    if (colors_out)
        (*colors_out)[at] = {color_byte(values[kRed], field_type[kRed], index),
                             color_byte(values[kGreen], field_type[kGreen], index),
                             color_byte(values[kBlue], field_type[kBlue], index)};
    if (radii_out) (*radii_out)[at] = float(values[kRadius]);
}

void PlyStream::Impl::emit_vertex(const double* values, uint64_t index, std::vector<Vec3d>& positions,
                                  std::vector<Vec3f>* normals_out, std::vector<Rgb8>* colors_out,
                                  std::vector<float>* radii_out) const {
    if (!mesh_io::finite3(values[kX], values[kY], values[kZ]))
        data_error(strprintf("vertex %llu has a non-finite coordinate (%g, %g, %g)", ull(index), values[kX],
                             values[kY], values[kZ]));
    if (normals_out && !mesh_io::finite3(values[kNx], values[kNy], values[kNz]))
        data_error(strprintf("vertex %llu has a non-finite normal", ull(index)));
    const size_t at = positions.size();
    positions.emplace_back();
    if (normals_out) normals_out->emplace_back();
    if (colors_out) colors_out->emplace_back();
    if (radii_out) radii_out->emplace_back();
    store_vertex(values, index, at, positions, normals_out, colors_out, radii_out);  // checks the colour
    if (radii_out && (!std::isfinite(values[kRadius]) || values[kRadius] < 0.0 || values[kRadius] > 3.0e38))
        data_error(strprintf("vertex %llu has an invalid radius (%g)", ull(index), values[kRadius]));
}

void PlyStream::Impl::check_index(int64_t index, uint64_t face) const {
    uint64_t vertices = elements[vertex_element].count;
    if (index < 0 || uint64_t(index) >= vertices)
        data_error(strprintf("face %llu uses vertex index %lld, out of range (%llu vertices)", ull(face),
                             (long long)index, ull(vertices)));
}

// ---------------------------------------------------------------------------------------------
// Body: binary

// Whether emit_vertex would take these values without an error (its tests and the colour's, no
// message).
bool PlyStream::Impl::vertex_valid(const double* values, bool normals_wanted, bool colors_wanted, bool radii_wanted) const {
    bool ok = mesh_io::finite3(values[kX], values[kY], values[kZ]);
    if (normals_wanted) ok &= mesh_io::finite3(values[kNx], values[kNy], values[kNz]);
    if (colors_wanted)
        for (int f = kRed; f <= kBlue; ++f)
            if (field_type[f] == PlyType::Float32 || field_type[f] == PlyType::Float64) ok &= std::isfinite(values[f]);
    if (radii_wanted) ok &= std::isfinite(values[kRadius]) && values[kRadius] >= 0.0 && values[kRadius] <= 3.0e38;
    return ok;
}

// Decodes k fixed-size vertices at `data` on all cores, appending them as emit_vertex would.
// Returns false, appending nothing, if any is invalid: the caller's serial loop then names the
// first. (Reading 100M points, 1.5 GB, took the point converter 4.8 s on one core.)
template <bool Swap>
bool PlyStream::Impl::parse_vertices_parallel(const char* data, size_t stride, size_t k, int last_field,
                                              std::vector<Vec3d>& positions, std::vector<Vec3f>* normals_out,
                                              std::vector<Rgb8>* colors_out, std::vector<float>* radii_out) const {
    const size_t base = positions.size();
    positions.resize(base + k);
    if (normals_out) normals_out->resize(base + k);
    if (colors_out) colors_out->resize(base + k);
    if (radii_out) radii_out->resize(base + k);
    std::atomic<bool> valid{true};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, k, 8192), [&](const tbb::blocked_range<size_t>& r) {
        double values[kFieldCount] = {};
        bool ok = true;
        for (size_t i = r.begin(); i < r.end(); ++i) {
            const char* p = data + i * stride;
            for (int f = 0; f <= last_field; ++f)
                if (field[f] != kNone) values[f] = load_double<Swap>(p + offset[f], field_type[f]);
            // An invalid vertex is not stored (its colour's conversion would throw): the batch is
            // decoded again in order anyway.
            if (vertex_valid(values, normals_out, colors_out, radii_out))
                store_vertex(values, 0, base + i, positions, normals_out, colors_out, radii_out);
            else
                ok = false;
        }
        if (!ok) valid.store(false, std::memory_order_relaxed);
    });
    if (valid.load()) return true;
    positions.resize(base);
    if (normals_out) normals_out->resize(base);
    if (colors_out) colors_out->resize(base);
    if (radii_out) radii_out->resize(base);
    return false;
}

template <bool Swap>
void PlyStream::Impl::read_vertices_binary(size_t n, std::vector<Vec3d>& positions, std::vector<Vec3f>* normals_out,
                                           std::vector<Rgb8>* colors_out, std::vector<float>* radii_out) {
    const PlyElement& vertex = elements[vertex_element];
    double values[kFieldCount] = {};
    if (!vertex.fixed_size) {  // rare: a list among the vertex properties
        for (size_t i = 0; i < n; ++i, ++done) {
            walk_binary_instance<Swap>(vertex, values);
            emit_vertex(values, done, positions, normals_out, colors_out, radii_out);
        }
        return;
    }
    const size_t stride = vertex.stride;
    const size_t batch = std::max<size_t>(1, kBatchBytes / stride);
    const int last_field = radii_out ? kRadius : colors_out ? kBlue : normals_out ? kNz : kZ;
    for (size_t first = 0; first < n;) {
        size_t k = std::min(n - first, batch);
        if (!file.ensure(k * stride)) {
            done += file.available() / stride;
            truncated();
        }
        const char* p = file.data();
        if (k < kParallelVertices ||
            !parse_vertices_parallel<Swap>(p, stride, k, last_field, positions, normals_out, colors_out, radii_out)) {
            for (size_t i = 0; i < k; ++i, p += stride) {
                for (int f = 0; f <= last_field; ++f)
                    if (field[f] != kNone) values[f] = load_double<Swap>(p + offset[f], field_type[f]);
                emit_vertex(values, done + i, positions, normals_out, colors_out, radii_out);
            }
        }
        file.consume(k * stride);
        first += k;
        done += k;
    }
}

// Reads one instance of a binary element, storing vertex fields in `values` when non-null.
template <bool Swap>
void PlyStream::Impl::walk_binary_instance(const PlyElement& element, double* values) {
    for (size_t p = 0; p < element.properties.size(); ++p) {
        const PlyProperty& property = element.properties[p];
        size_t size = type_size(property.list ? property.count_type : property.type);
        if (!file.ensure(size)) truncated();
        if (property.list) {
            int64_t count = load_int<Swap>(file.data(), property.count_type);
            file.consume(size);
            if (count < 0) data_error(strprintf("%s %llu has a negative list length", element.name.c_str(), ull(done)));
            uint64_t bytes = uint64_t(count) * type_size(property.type);
            if (file.skip(bytes) < bytes) truncated();
            continue;
        }
        if (values) {
            for (int f = 0; f < kFieldCount; ++f)
                if (field[f] == p) values[f] = load_double<Swap>(file.data(), property.type);
        }
        file.consume(size);
    }
}

template <bool Swap>
void PlyStream::Impl::read_faces_binary(size_t n, std::vector<uint32_t>& indices) {
    const PlyElement& face = elements[face_element];
    for (size_t i = 0; i < n;) {
        if (face.properties.size() == 1) {  // the usual layout: nothing but the index list
            size_t fast = read_triangles_in_buffer<Swap>(n - i, indices);
            i += fast;
            if (i == n) break;
        }
        read_face_binary<Swap>(indices);  // anything else: polygons, other properties, errors
        ++i;
    }
}

// The fast path for faces that are only an index list: decodes, straight from the buffer, the
// triangles whose indices are in range, and stops (for read_face_binary to deal with) at the
// first face that is not such a triangle or does not fit in the buffer.
template <bool Swap>
size_t PlyStream::Impl::read_triangles_in_buffer(size_t max, std::vector<uint32_t>& indices) {
    const PlyProperty& list = elements[face_element].properties[0];
    const size_t count_size = type_size(list.count_type), item_size = type_size(list.type);
    const size_t face_size = count_size + 3 * item_size;
    const uint64_t vertices = elements[vertex_element].count;
    const char* p = file.data();
    const char* end = p + file.available();
    size_t n = 0;
    for (; n < max && size_t(end - p) >= face_size; ++n, p += face_size) {
        if (load_int<Swap>(p, list.count_type) != 3) break;
        int64_t a = load_int<Swap>(p + count_size, list.type);
        int64_t b = load_int<Swap>(p + count_size + item_size, list.type);
        int64_t c = load_int<Swap>(p + count_size + 2 * item_size, list.type);
        // Negative values wrap to huge unsigned ones, so one comparison per index suffices.
        if (uint64_t(a) >= vertices || uint64_t(b) >= vertices || uint64_t(c) >= vertices) break;
        mesh_io::push_triangle(indices, uint32_t(a), uint32_t(b), uint32_t(c));
    }
    file.consume(size_t(p - file.data()));
    done += n;
    return n;
}

// Reads one face, all its properties, appending the fan triangulation of its index list.
template <bool Swap>
void PlyStream::Impl::read_face_binary(std::vector<uint32_t>& indices) {
    const PlyElement& face = elements[face_element];
    for (size_t p = 0; p < face.properties.size(); ++p) {
        const PlyProperty& property = face.properties[p];
        if (p == index_list) {
            read_index_list_binary<Swap>(property, done, indices);
            continue;
        }
        size_t size = type_size(property.list ? property.count_type : property.type);
        if (!file.ensure(size)) truncated();
        int64_t count = property.list ? load_int<Swap>(file.data(), property.count_type) : 0;
        file.consume(size);
        if (count < 0) data_error(strprintf("face %llu has a negative list length", ull(done)));
        uint64_t bytes = uint64_t(count) * type_size(property.type);
        if (file.skip(bytes) < bytes) truncated();
    }
    ++done;
}

// Reads one face's index list and appends its fan triangulation. Long lists are decoded in
// batches so a hostile count cannot make the buffer grow without bound.
template <bool Swap>
void PlyStream::Impl::read_index_list_binary(const PlyProperty& list, uint64_t face, std::vector<uint32_t>& indices) {
    size_t count_size = type_size(list.count_type), item_size = type_size(list.type);
    if (!file.ensure(count_size)) truncated();
    int64_t count = load_int<Swap>(file.data(), list.count_type);
    file.consume(count_size);
    if (count < 3)
        data_error(strprintf("face %llu has %lld vertices (fewer than 3)", ull(face), (long long)count));
    uint32_t first = 0, previous = 0;
    for (int64_t corner = 0; corner < count;) {
        size_t k = size_t(std::min<int64_t>(count - corner, int64_t(kBatchBytes / item_size)));
        if (!file.ensure(k * item_size)) truncated();
        const char* p = file.data();
        for (size_t i = 0; i < k; ++i, ++corner, p += item_size) {
            int64_t index = load_int<Swap>(p, list.type);
            check_index(index, face);
            if (corner == 0) {
                first = uint32_t(index);
            } else if (corner >= 2) {
                mesh_io::push_triangle(indices, first, previous, uint32_t(index));
            }
            previous = uint32_t(index);
        }
        file.consume(k * item_size);
    }
}

// ---------------------------------------------------------------------------------------------
// Body: ascii (one element instance per line, as every PLY writer does; this is what lets a
// wrong count in the header be reported instead of silently shifting values between elements)

std::string_view PlyStream::Impl::next_data_line() {
    std::string_view line;
    for (;;) {
        if (!file.next_line(line)) {
            const PlyElement& element = elements[current];
            file.fail("truncated: the file ends after %llu of %llu %s elements", ull(done), ull(element.count),
                      element.name.c_str());
        }
        Tokens tokens(line);
        if (!tokens.empty()) return line;
    }
}

double PlyStream::Impl::ascii_value(Tokens& tokens, const PlyElement& element, PlyType type,
                                    const std::string& name) const {
    std::string_view token;
    if (!tokens.next(token))
        file.fail_line("too few values for %s %llu (the header declares more properties)", element.name.c_str(),
                       ull(done));
    if (is_integer(type)) {
        int64_t value;
        if (!mesh_io::parse_int(token, value) || !in_range(value, type))
            file.fail_line("expected a %s for property '%s', found %s", type_name(type), name.c_str(),
                           quoted(token).c_str());
        return double(value);
    }
    bool ok;
    double value;
    if (type == PlyType::Float32) {
        float single = 0.0f;
        ok = mesh_io::parse_float(token, single);
        value = single;
    } else {
        ok = mesh_io::parse_double(token, value);
    }
    if (!ok) file.fail_line("expected a number for property '%s', found %s", name.c_str(), quoted(token).c_str());
    return value;
}

void PlyStream::Impl::read_vertices_ascii(size_t n, std::vector<Vec3d>& positions, std::vector<Vec3f>* normals_out,
                                          std::vector<Rgb8>* colors_out, std::vector<float>* radii_out) {
    const PlyElement& vertex = elements[vertex_element];
    double values[kFieldCount] = {};
    for (size_t i = 0; i < n; ++i, ++done) {
        Tokens tokens(next_data_line());
        for (size_t p = 0; p < vertex.properties.size(); ++p) {
            const PlyProperty& property = vertex.properties[p];
            if (property.list) {
                int64_t items = int64_t(ascii_value(tokens, vertex, property.count_type, property.name));
                for (int64_t k = 0; k < items; ++k) ascii_value(tokens, vertex, property.type, property.name);
                continue;
            }
            double value = ascii_value(tokens, vertex, property.type, property.name);
            for (int f = 0; f < kFieldCount; ++f)
                if (field[f] == p) values[f] = value;
        }
        if (!tokens.empty()) file.fail_line("more values than the header declares for vertex %llu", ull(done));
        emit_vertex(values, done, positions, normals_out, colors_out, radii_out);
    }
}

void PlyStream::Impl::read_faces_ascii(size_t n, std::vector<uint32_t>& indices) {
    const PlyElement& face = elements[face_element];
    for (size_t i = 0; i < n; ++i, ++done) {
        Tokens tokens(next_data_line());
        for (size_t p = 0; p < face.properties.size(); ++p) {
            const PlyProperty& property = face.properties[p];
            if (!property.list) {
                ascii_value(tokens, face, property.type, property.name);
                continue;
            }
            int64_t count = int64_t(ascii_value(tokens, face, property.count_type, property.name));
            if (p == index_list && count < 3)
                file.fail_line("face %llu has %lld vertices (fewer than 3)", ull(done), (long long)count);
            uint32_t first = 0, previous = 0;
            for (int64_t corner = 0; corner < count; ++corner) {
                double value = ascii_value(tokens, face, property.type, property.name);
                if (p != index_list) continue;
                int64_t index = int64_t(value);
                check_index(index, done);
                if (corner == 0) first = uint32_t(index);
                else if (corner >= 2) mesh_io::push_triangle(indices, first, previous, uint32_t(index));
                previous = uint32_t(index);
            }
        }
        if (!tokens.empty()) file.fail_line("more values than the header declares for face %llu", ull(done));
    }
}

// ---------------------------------------------------------------------------------------------
// PlyStream

PlyStream::PlyStream(const std::string& path) : impl_(std::make_unique<Impl>(path)) { impl_->parse_header(); }

PlyStream::~PlyStream() = default;

uint64_t PlyStream::vertex_count() const { return impl_->elements[impl_->vertex_element].count; }

uint64_t PlyStream::face_count() const {
    return impl_->face_element == kNone ? 0 : impl_->elements[impl_->face_element].count;
}

bool PlyStream::has_normals() const { return impl_->normals; }
bool PlyStream::has_colors() const { return impl_->colors; }
bool PlyStream::has_radii() const { return impl_->radii; }

std::vector<std::string> PlyStream::dropped(bool keeps_radii) const {
    const Impl& s = *impl_;
    std::vector<std::string> out;
    auto names = [](const std::vector<std::string>& list) {
        std::string text;
        for (const std::string& n : list) text += (text.empty() ? "" : ", ") + n;
        return text;
    };
    std::vector<std::string> unused;
    const PlyElement& vertex = s.elements[s.vertex_element];
    for (size_t p = 0; p < vertex.properties.size(); ++p) {
        bool used = false;
        for (int f = 0; f < kFieldCount; ++f)
            // Normals and colours only count when all three components are there.
            used |= s.field[f] == p &&
                    (f < kNx || (f < kRed ? s.normals : f < kRadius ? s.colors : keeps_radii));
        if (!used) unused.push_back(vertex.properties[p].name);
    }
    if (!unused.empty()) out.push_back("vertex properties " + names(unused) + " (not kept)");
    if (s.face_element != kNone) {
        const PlyElement& face = s.elements[s.face_element];
        std::vector<std::string> colour, other;
        for (size_t p = 0; p < face.properties.size(); ++p) {
            if (p == s.index_list) continue;
            const std::string& n = face.properties[p].name;
            bool is_colour = n == "red" || n == "green" || n == "blue" || n == "alpha" || n == "r" || n == "g" || n == "b";
            (is_colour ? colour : other).push_back(n);
        }
        if (!colour.empty())
            out.push_back(strprintf("face colours (%s) of %llu faces: colours are kept per vertex only",
                                    names(colour).c_str(), ull(face.count)));
        if (!other.empty()) out.push_back("face properties " + names(other) + " (not kept)");
    }
    for (size_t e = 0; e < s.elements.size(); ++e)
        if (e != s.vertex_element && e != s.face_element && s.elements[e].count > 0)
            out.push_back(strprintf("%llu '%s' elements (not kept)", ull(s.elements[e].count), s.elements[e].name.c_str()));
    return out;
}

size_t PlyStream::read_vertices(size_t max, std::vector<Vec3d>& positions, std::vector<Vec3f>* normals,
                                std::vector<Rgb8>* colors, std::vector<float>* radii) {
    Impl& s = *impl_;
    assert(!normals || s.normals);
    assert(!colors || s.colors);
    assert(!radii || s.radii);
    if (s.current > s.vertex_element) return 0;
    s.advance_to(s.vertex_element);
    size_t n = size_t(std::min<uint64_t>(max, s.elements[s.vertex_element].count - s.done));
    if (n == 0) return 0;
    if (s.ascii()) s.read_vertices_ascii(n, positions, normals, colors, radii);
    else if (s.swap()) s.read_vertices_binary<true>(n, positions, normals, colors, radii);
    else s.read_vertices_binary<false>(n, positions, normals, colors, radii);
    s.end_of_batch();
    return n;
}

size_t PlyStream::read_faces(size_t max, std::vector<uint32_t>& indices) {
    Impl& s = *impl_;
    if (s.face_element == kNone || s.current > s.face_element) return 0;
    s.advance_to(s.face_element);
    size_t n = size_t(std::min<uint64_t>(max, s.elements[s.face_element].count - s.done));
    if (n == 0) return 0;
    if (s.ascii()) s.read_faces_ascii(n, indices);
    else if (s.swap()) s.read_faces_binary<true>(n, indices);
    else s.read_faces_binary<false>(n, indices);
    s.end_of_batch();
    return n;
}

void PlyStream::finish() {
    Impl& s = *impl_;
    s.advance_to(s.elements.size());
    if (!s.file.only_whitespace_left())
        s.file.fail("the element counts in the header do not match the data: more data follows the last element");
}

namespace mesh_io {

Mesh read_ply(const std::string& path, std::vector<std::string>& dropped) {
    PlyStream stream(path);
    dropped = stream.dropped();
    Mesh mesh;
    // The header check bounds these counts by the file size, so reserving is safe.
    mesh_io::reserve_huge(mesh.positions, stream.vertex_count());
    if (stream.has_normals()) mesh_io::reserve_huge(mesh.normals, stream.vertex_count());
    if (stream.has_colors()) mesh_io::reserve_huge(mesh.colors, stream.vertex_count());
    std::vector<Vec3f>* normals = stream.has_normals() ? &mesh.normals : nullptr;
    std::vector<Rgb8>* colors = stream.has_colors() ? &mesh.colors : nullptr;
    while (stream.read_vertices(size_t(1) << 20, mesh.positions, normals, colors) > 0) {
    }
    mesh_io::reserve_huge(mesh.indices, stream.face_count() * 3);
    while (stream.read_faces(size_t(1) << 20, mesh.indices) > 0) {
    }
    stream.finish();
    return mesh;
}

}  // namespace mesh_io
}  // namespace catpaq
