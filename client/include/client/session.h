#pragma once
// A streaming session: one dataset (local path or URL) of any format, its hierarchy, the cut
// engine, the asynchronous fetcher, the decoded nodes, the compressed cache and the format's GPU
// store, stepped once per frame. Used by `catpaq render` (headless) and the desktop viewer. Only
// the thread that owns the GL context calls step() and draw(); fetching and decoding run on the
// fetcher's threads.
//
// The session knows nodes, keys, byte ranges, bounds, errors and dependencies; the dataset's
// format (client/format.h), chosen by the archive kind from SessionSettings::formats, decodes,
// measures and draws.
#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "client/cache.h"
#include "client/camera.h"
#include "client/cut_engine.h"
#include "client/fetcher.h"
#include "client/format.h"
#include "client/hierarchy.h"
#include "client/node_renderer.h"

namespace catpaq {

struct SessionSettings {
    double tolerance_px = 1.5;
    // ViewParams::skip_factor (0: fetch every level). 8 measured on the report's 2M-triangle
    // scan, cold start to 1.5 px: the zoom's last view fetched 2.75 MB instead of 4.61 (2 gave
    // 3.90, 4 2.89, 16 2.52), the fly's first 2.04 instead of 3.63, for the same cut, converging
    // sooner (fewer round trips); 16 makes the first previews coarser for little more.
    // Datasets whose nodes decode against their parents (AQP) fetch every level whatever it says.
    double skip_factor = 8;
    CutBudgets budgets;               // primitives, GPU and CPU bytes of the cut, requests
    uint64_t gpu_cache_bytes = 512ull << 20;         // GPU store budget (cut + recently used)
    uint64_t compressed_cache_bytes = 256ull << 20;  // compressed nodes kept for re-decoding
    HttpSettings http;
    FetcherSettings fetcher;  // its decoder is the dataset format's
    // Fetch a node's parts one by one where the format can (HierarchyNode::fetch_parts): a
    // refinement fetches only what it draws. false: whole nodes (to compare; `render
    // --fetch-whole-nodes`).
    bool fetch_parts = true;
    // The formats the session can stream, by archive kind; nullptr: this build's
    // (builtin_formats(), client/builtin_formats.h). Must outlive the session.
    const FormatRegistry* formats = nullptr;
};

// A node the session could not get: its fetch or decode failed every attempt (the fetcher
// tries it again later while it is wanted; the cut keeps its coarser ancestor meanwhile).
struct NodeFailure {
    uint64_t key = 0;
    uint16_t level = 0;
    std::string error;  // the last problem: HTTP status, checksum mismatch, bytes past the end, ...
};

// Why the certified error is above the tolerance (bits of SessionFrameStats::limits).
enum SessionLimit : uint8_t {
    kLimitFinestLevel = 1,     // drawn finest-level nodes are over the tolerance
    kLimitTriangles = 2,       // a refinement would pass --max-triangles
    kLimitGpuBytes = 4,        // ... the GPU budget
    kLimitCpuBytes = 8,        // ... the CPU budget
    kLimitFailedNode = 16,     // a node the cut needs failed (NodeFailure)
    kLimitPending = 32,        // data the cut needs is still on its way
};
// The names of the set bits, as JSON strings ("finest_level", "triangle_budget", ...).
std::vector<const char*> session_limit_names(uint8_t limits);

// Statistics of one step (what `render --stats` writes per frame: docs/formats/stats.md).
struct SessionFrameStats {
    uint64_t triangles = 0;       // drawn this frame
    size_t drawn_nodes = 0, refined_nodes = 0, fragments = 0;
    uint64_t bytes_fetched = 0;   // since the session started (including the prefix)
    uint64_t requests = 0;        // node transfers since the start
    size_t pending = 0;           // wanted nodes not resident yet
    uint64_t gpu_bytes = 0, cpu_bytes = 0;
    double cut_ms = 0;
    double certified_error_px = 0;  // largest projected error of any drawn node
    size_t holes = 0;             // drawn nodes in the view whose data is not resident yet
    size_t arrived = 0;           // nodes integrated by this step
    uint32_t cut_changes = 0;     // refinements and coarsenings of this step
    size_t failed_nodes = 0;      // failures so far (StreamingSession::failures)
    // Nothing pending: no request outstanding, nothing arriving, every drawn node resident and
    // the cut stable for this camera. Says nothing about the error (tolerance_met does).
    bool settled = false;
    // The certified error is within the tolerance (and no drawn node is a hole).
    bool tolerance_met = false;
    uint8_t limits = 0;  // SessionLimit bits: what kept the error above the tolerance
};

class StreamingSession {
public:
    // Loads the prefix and builds the hierarchy (throws Error). A GL context must be current.
    StreamingSession(const std::string& location, const SessionSettings& settings);
    ~StreamingSession();

    const DatasetFormat& format() const { return *format_; }
    const Hierarchy& hierarchy() const { return format_->hierarchy(); }
    const SessionSettings& settings() const { return settings_; }
    void set_tolerance(double px) { settings_.tolerance_px = px; }

    // Integrates arrived nodes, updates the cut for the camera and issues requests. Never waits.
    SessionFrameStats step(const Camera& camera);
    // True when nothing is being fetched and every drawn node is resident with the cut stable
    // for the last step's camera (SessionFrameStats::settled of the last step).
    bool settled() const { return settled_; }
    // Nodes that failed every attempt so far, in the order they failed (each once).
    const std::vector<NodeFailure>& failures() const { return failures_; }
    // Draws the current cut into the bound framebuffer.
    RenderStats draw(const Camera& camera, const RenderSettings& render);
    // The (node, part) pairs drawn by the current cut (resident on the GPU).
    const std::vector<DrawnPart>& items() const { return items_; }
    // Decoded data holding part `part` (HierarchyPart::id) of a node, or nullptr if that part is
    // not resident.
    const DecodedNode* decoded(uint64_t key, uint8_t part) const;
    // The geometry of items() as drawn, in a frame near `eye` (DatasetFormat::drawn_geometry):
    // what picking and render --export-cut use.
    DrawnGeometry drawn_geometry(const std::array<double, 3>& eye) const;

private:
    void integrate(std::vector<FetchedNode>& arrived);
    double data_distance(uint32_t node, const std::array<double, 3>& eye);
    uint8_t limits(const CutFrame& frame, const SessionFrameStats& s) const;
    void evict(uint32_t node);
    void evict_part(uint32_t node, size_t part);
    // The decoded data holding part index `part` of a resident node, or nullptr.
    const DecodedNode* decoded_part(uint32_t node, size_t part) const;

    SessionSettings settings_;
    std::unique_ptr<DatasetFormat> format_;
    std::unique_ptr<PartDrawCounter> counter_;
    std::unique_ptr<ResidencyTable> residency_;
    std::unique_ptr<CutEngine> engine_;
    std::unique_ptr<Fetcher> fetcher_;
    // The format's GPU store and renderer: evicting a part there drops its node (evict()).
    std::unique_ptr<NodeRenderer> renderer_;
    // A resident node's decoded data: the whole node, or (fetched by parts) one per part index.
    struct NodeData {
        std::shared_ptr<const DecodedNode> whole;
        std::vector<std::shared_ptr<const DecodedNode>> parts;
    };
    std::unordered_map<uint32_t, NodeData> decoded_;
    // Nodes evicted from the GPU and wanted again are decoded from here instead of refetched.
    std::unique_ptr<CompressedCache> compressed_;
    std::unordered_set<uint64_t> supplied_;  // fetch ids handed to the fetcher, not arrived yet
    std::vector<DrawnPart> items_;
    uint64_t prefix_bytes_ = 0;
    // The first request's bytes past the prefix (level 0's payloads, and from a static server
    // whatever else its first 64 KiB held) and their file offset: fetches inside them are
    // served from here (Fetcher::supply), not fetched a second time.
    std::vector<uint8_t> first_nodes_;
    uint64_t first_nodes_offset_ = 0;
    std::unordered_set<uint64_t> from_first_request_;  // supplied from first_nodes_, not arrived yet
    bool settled_ = false;
    std::vector<NodeFailure> failures_;
    // data_distance's last measure per node: the eye it was taken from and the distance.
    struct MeasuredDistance {
        std::array<double, 3> eye;
        double distance;
    };
    std::unordered_map<uint32_t, MeasuredDistance> distances_;
    std::unordered_set<uint64_t> failed_keys_;  // failed and not delivered since
};

}  // namespace catpaq
