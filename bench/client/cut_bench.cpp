// cut_bench: the cost of CutEngine::update (client/cut_engine.h) per frame over a camera path on a
// big synthetic hierarchy (~100k nodes, build_synthetic_hierarchy), with the incremental front
// against a baseline measured in the same run: the same engine rebuilding the cut from the root
// every frame (reset() then update()).
//
//   cut_bench [--levels N] [--keep P] [--frames N] [--tolerance PX] [--seed S]
//
// Scenarios: everything resident with unlimited budgets; a binding primitive budget (swaps);
// data arriving two frames after it is requested (requests, holes, waiting refinements).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include "client/cut_engine.h"
#include "client/hierarchy.h"

using namespace catpaq;

namespace {

struct Args {
    int levels = 10;
    double keep = 0.87;
    int frames = 600;
    double tolerance = 0.5;
    uint64_t seed = 1;
};

Args parse(int argc, char** argv) {
    Args a;
    for (int i = 1; i + 1 < argc; i += 2) {
        std::string k = argv[i];
        const char* v = argv[i + 1];
        if (k == "--levels") a.levels = std::atoi(v);
        else if (k == "--keep") a.keep = std::atof(v);
        else if (k == "--frames") a.frames = std::atoi(v);
        else if (k == "--tolerance") a.tolerance = std::atof(v);
        else if (k == "--seed") a.seed = std::strtoull(v, nullptr, 10);
        else {
            std::fprintf(stderr, "unknown option %s\n", k.c_str());
            std::exit(2);
        }
    }
    return a;
}

constexpr double kSize = 10000.0;

// A low flight over the terrain with turns, climbs and a dive: the front moves every frame.
ViewParams view(int frame, int frames, double tolerance) {
    double t = double(frame) / double(frames);
    double a = t * 2 * M_PI;
    std::array<double, 3> eye{kSize * (0.5 + 0.4 * std::cos(a)), kSize * (0.5 + 0.4 * std::sin(2 * a)),
                              30 + 600 * (0.5 + 0.5 * std::sin(3 * a))};
    std::array<double, 3> target{kSize * (0.5 + 0.4 * std::cos(a + 0.2)), kSize * (0.5 + 0.4 * std::sin(2 * a + 0.4)), 0};
    ViewParams v = ViewParams::look_at(eye, target, {0, 0, 1}, 60 * M_PI / 180, 1920, 1080, 0.1, 1e6);
    v.tolerance_px = tolerance;
    return v;
}

class AllResident : public Residency {
public:
    explicit AllResident(const Hierarchy& h) : h_(h) {}
    bool resident(uint32_t) const override { return true; }
    NodeBytes bytes(uint32_t n) const override {
        uint64_t p = h_.node(n).primitives;
        return {p * 16, p * 20 + 64};
    }
    bool changes_since(uint64_t&, std::vector<uint32_t>&) const override { return true; }  // nothing ever changes

private:
    const Hierarchy& h_;
};

// Data arrives `delay` frames after it is requested.
class Delayed : public Residency {
public:
    Delayed(const Hierarchy& h, int delay) : h_(h), delay_(delay), resident_(h.size(), 0) {}
    bool resident(uint32_t n) const override { return resident_[n] != 0; }
    NodeBytes bytes(uint32_t n) const override {
        uint64_t p = h_.node(n).primitives;
        return {p * 16, p * 20 + 64};
    }
    bool changes_since(uint64_t& cursor, std::vector<uint32_t>& out) const override { return log_.since(cursor, out); }
    void frame(const CutFrame& f) {
        now_++;
        for (const CutRequest& c : f.cancelled) due_.erase(c.node);
        for (const CutRequest& r : f.requests)
            if (!due_.count(r.node)) due_[r.node] = now_ + delay_;
        for (auto it = due_.begin(); it != due_.end();) {
            if (it->second <= now_) {
                resident_[it->first] = 1;
                log_.add(it->first);
                it = due_.erase(it);
            } else {
                ++it;
            }
        }
    }

private:
    const Hierarchy& h_;
    int delay_;
    std::vector<uint8_t> resident_;
    std::map<uint32_t, int64_t> due_;
    int64_t now_ = 0;
    ChangeLog log_;
};

struct Summary {
    std::vector<double> us;
    double drawn = 0, refined = 0, primitives = 0, ops = 0, requests = 0, certified = 0;

    void add(double micros, const CutFrameStats& s, size_t requests_made) {
        us.push_back(micros);
        drawn += double(s.drawn_nodes);
        refined += double(s.refined_nodes);
        primitives += double(s.primitives);
        ops += double(s.refinements + s.coarsenings);
        requests += double(requests_made);
        certified = std::max(certified, s.certified_error_px);
    }
    double mean() const {
        double sum = 0;
        for (double x : us) sum += x;
        return us.empty() ? 0 : sum / double(us.size());
    }
    double percentile(double p) const {
        std::vector<double> v = us;
        std::sort(v.begin(), v.end());
        return v.empty() ? 0 : v[std::min(v.size() - 1, size_t(p * double(v.size())))];
    }
    void print(const char* name) const {
        double n = double(std::max<size_t>(1, us.size()));
        std::printf("  %-34s %9.1f %9.1f %9.1f %9.1f   %8.0f %8.0f %10.0f %7.1f %6.1f\n", name, mean(), percentile(0.5),
                    percentile(0.95), percentile(1.0), drawn / n, refined / n, primitives / n, ops / n, requests / n);
    }
};

double micros_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
    Args args = parse(argc, argv);
    SyntheticHierarchySettings s;
    s.levels = args.levels;
    s.keep = args.keep;
    s.extra_parent = 0.35;
    s.virtual_fraction = 0.05;
    s.size = kSize;
    s.seed = args.seed;
    auto t0 = std::chrono::steady_clock::now();
    Hierarchy h = build_synthetic_hierarchy(s);
    double build_ms = micros_since(t0) / 1000;
    size_t edges = 0;
    for (const HierarchyNode& n : h.nodes()) edges += n.parents.size();
    std::printf("cut_bench: synthetic hierarchy of %zu nodes (%zu virtual, %zu parent links, %d levels), built in %.0f ms\n",
                h.size(), h.virtual_count(), edges, args.levels, build_ms);
    std::printf("camera path: %d frames, 1920x1080, 60 deg, tolerance %.2f px\n\n", args.frames, args.tolerance);
    std::printf("  %-34s %9s %9s %9s %9s   %8s %8s %10s %7s %6s\n", "scenario (us per update)", "mean", "median", "p95", "max",
                "drawn", "refined", "primitives", "ops", "reqs");

    PartDrawCounter counter(h);
    AllResident all(h);

    // Baseline: the cut rebuilt from the root every frame (no front kept between frames).
    Summary scratch;
    {
        CutEngine engine(h, counter);
        for (int f = 1; f <= args.frames; ++f) {
            auto t = std::chrono::steady_clock::now();
            engine.reset();
            const CutFrame& fr = engine.update(view(f, args.frames, args.tolerance), all);
            scratch.add(micros_since(t), fr.stats, fr.requests.size());
        }
    }
    scratch.print("baseline: from the root each frame");

    // The incremental front.
    Summary front;
    {
        CutEngine engine(h, counter);
        engine.update(view(0, args.frames, args.tolerance), all);  // first cut outside the timing
        for (int f = 1; f <= args.frames; ++f) {
            auto t = std::chrono::steady_clock::now();
            const CutFrame& fr = engine.update(view(f, args.frames, args.tolerance), all);
            front.add(micros_since(t), fr.stats, fr.requests.size());
        }
    }
    front.print("incremental front, all resident");

    // A binding primitive budget: half of what the unlimited cut draws on average.
    Summary budgeted;
    {
        CutBudgets b;
        b.max_primitives = uint64_t(front.primitives / double(front.us.size()) / 2);
        CutEngine engine(h, counter, b);
        engine.update(view(0, args.frames, args.tolerance), all);
        for (int f = 1; f <= args.frames; ++f) {
            auto t = std::chrono::steady_clock::now();
            const CutFrame& fr = engine.update(view(f, args.frames, args.tolerance), all);
            budgeted.add(micros_since(t), fr.stats, fr.requests.size());
        }
        char name[64];
        std::snprintf(name, sizeof(name), "front, budget %llu primitives", (unsigned long long)b.max_primitives);
        budgeted.print(name);
    }

    // Streaming: data arrives two frames after the request (32 new requests per frame).
    Summary streaming;
    {
        Delayed delayed(h, 2);
        CutBudgets b;
        b.max_new_requests = 32;
        CutEngine engine(h, counter, b);
        for (int f = 0; f <= args.frames; ++f) {
            auto t = std::chrono::steady_clock::now();
            const CutFrame& fr = engine.update(view(f, args.frames, args.tolerance), delayed);
            if (f > 0) streaming.add(micros_since(t), fr.stats, fr.requests.size());
            delayed.frame(fr);
        }
    }
    streaming.print("front, streaming (2-frame latency)");

    std::printf("\nincremental front vs rebuilding from the root: %.1fx less time per frame (mean)\n",
                scratch.mean() / std::max(1e-9, front.mean()));
    std::printf("columns: drawn/refined nodes, primitives, refinements+coarsenings and requests are per-frame means\n");
    return 0;
}
