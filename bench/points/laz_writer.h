#pragma once
// A LAS 1.2 / LAZ writer for the benchmark's comparison with LAZ (issue 18): bench-only code, not
// part of the product (the product reads LAS, points/src/read_las.cpp, and never writes LAZ).
//
// Point data format 2 (X, Y, Z as int32, intensity, the return/flags byte, classification, scan
// angle rank, user data, point source ID, RGB as three uint16), or format 0 without colours.
// Compressed, the file is standard LASzip "pointwise chunked" LAZ as LASzip 2.x and later write
// it and every LAZ reader reads it: compressor 2, items POINT10 version 2 (and RGB12 version 2),
// a "laszip encoded" VLR (record 22204) listing them, chunks of a fixed number of points (each
// starts with its first point raw, then LASzip's adaptive arithmetic coder), the chunk table at
// the end and its file offset in the 8 bytes at the start of the point data. Our own code,
// written from the format as LASzip defines it (its public source read for the exact model
// updates); tests/points/test_laz_writer.cpp checks the files against an independent decoder
// (laz-perf, scripts/report/laz_decode.mjs), point for point, bit for bit.
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace catpaq::laz {

// One point record of LAS point data format 0 or 2, fields as the format stores them.
struct LasPoint {
    int32_t x = 0, y = 0, z = 0;  // coordinate = integer * scale + offset
    uint16_t intensity = 0;
    uint8_t return_number = 1;      // 3 bits: 0..7
    uint8_t number_of_returns = 1;  // 3 bits: 0..7
    bool scan_direction = false, edge_of_flight_line = false;
    uint8_t classification = 0;
    int8_t scan_angle_rank = 0;
    uint8_t user_data = 0;
    uint16_t point_source_id = 0;
    uint16_t rgb[3] = {0, 0, 0};  // format 2 only
};

// The header's coordinate system and the point format.
struct LasLayout {
    double scale[3] = {0.001, 0.001, 0.001};
    double offset[3] = {0, 0, 0};
    bool colors = true;  // point data format 2 (RGB), else format 0
};

// LASzip's chunk size (points per chunk) when none is given: LASzip's own default.
constexpr uint32_t kDefaultChunkPoints = 50000;

struct LasFileSummary {
    uint64_t file_bytes = 0;
    uint64_t point_bytes = 0;  // the point data: records, or for LAZ the chunks and chunk table
    uint32_t chunks = 0;       // LAZ only
};

// Bytes of one record: 20 for format 0, 26 for format 2.
size_t las_record_length(bool colors);

// Appends the record's bytes as LAS stores them (little-endian) to `out`.
void append_las_record(const LasPoint& point, bool colors, std::string& out);

// The points quantized to the layout: integer = round((coordinate - offset) / scale); colours
// from 8 bits to LAS's 16 as v * 257 (the product's convention, write_las). Throws Error naming
// the point when a coordinate is not finite or its integer does not fit int32.
std::vector<LasPoint> quantize_points(const std::vector<std::array<double, 3>>& positions,
                                      const std::vector<std::array<uint8_t, 3>>& colors, const LasLayout& layout);

// Writes a LAS 1.2 file (uncompressed) or a LAZ file (`compressed`) holding `points`, atomically
// (base/atomic_file.h). Throws Error on a bad layout (scale not finite and positive, chunk size 0)
// or a field out of its bits (return number or number of returns above 7), or on a write error.
LasFileSummary write_las_file(const std::string& path, const std::vector<LasPoint>& points, const LasLayout& layout,
                              bool compressed, uint32_t chunk_points = kDefaultChunkPoints);

// The LAZ bytes alone (what write_las_file writes when compressed), for callers that keep them.
std::string encode_laz(const std::vector<LasPoint>& points, const LasLayout& layout,
                       uint32_t chunk_points = kDefaultChunkPoints, uint32_t* chunks = nullptr);

// The independent check: scripts/report/laz_decode.mjs run by node, decoding with laz-perf
// (npm laz-perf@0.0.7, which `scripts/setup.sh --tests` installs under $CATPAQ_NPM_DIR, by default
// ~/.cache/catpaq-npm).
struct LazPerfDecoder {
    std::string node;     // the node executable (found in PATH)
    std::string script;   // laz_decode.mjs
    std::string modules;  // the directory whose node_modules holds laz-perf
};

// Finds node, the script under `source_dir` and laz-perf; throws Error saying which is missing
// and how to install it.
LazPerfDecoder find_lazperf_decoder(const std::string& source_dir);

struct DecodedLas {
    uint64_t points = 0;
    int format = -1;
    int record_length = 0;
    std::string records;  // every point record as LAS stores it, in file order
};

// Decodes `path` (LAZ or LAS) with laz-perf; `scratch` is a file name for the records on their
// way back (removed after). Throws Error with the decoder's message when it fails.
DecodedLas decode_with_lazperf(const LazPerfDecoder& decoder, const std::string& path, const std::string& scratch);

}  // namespace catpaq::laz
