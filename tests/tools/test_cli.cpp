// The catpaq tool on bad input and bad options: a clear message, a non-zero exit, nothing
// half-written; and the happy path convert -> verify.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <csignal>
#include <cstring>
#include <sys/wait.h>
#include <unistd.h>

#include "base/atomic_file.h"
#include "base/child_process.h"
#include "mesh/generators.h"
#include "mesh/io.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

struct ToolRun {
    int status = -1;
    std::string output;  // stdout and stderr
};

fs::path scratch() {
    static fs::path dir = [] {
        fs::path d = fs::temp_directory_path() / ("catpaq_cli_" + std::to_string(getpid()));
        fs::create_directories(d);
        return d;
    }();
    return dir;
}

ToolRun run(const std::string& args) {
    std::string command = std::string(CATPAQ_BINARY_DIR) + "/apps/catpaq " + args + " 2>&1";
    ToolRun r;
    FILE* pipe = popen(command.c_str(), "r");
    char buffer[4096];
    size_t n;
    while ((n = fread(buffer, 1, sizeof buffer, pipe)) > 0) r.output.append(buffer, n);
    int status = pclose(pipe);
    r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}

void write_text(const fs::path& path, const std::string& text) { std::ofstream(path) << text; }

// No output and no temporary left next to it.
void expect_nothing_written(const fs::path& output) {
    EXPECT_FALSE(fs::exists(output)) << output;
    for (auto& e : fs::directory_iterator(output.parent_path()))
        EXPECT_EQ(e.path().filename().string().find(output.filename().string() + "."), std::string::npos) << e.path();
}

void expect_failure(const std::string& args, const std::string& message_part) {
    ToolRun r = run(args);
    EXPECT_NE(r.status, 0) << args << "\n" << r.output;
    EXPECT_NE(r.output.find(message_part), std::string::npos) << "expected '" << message_part << "' in:\n" << r.output;
}

}  // namespace

TEST(Cli, ConvertThenVerifySucceedsOnAGeneratedSphere) {
    fs::path in = scratch() / "sphere.ply", out = scratch() / "sphere.cpq";
    write_ply(in.string(), make_sphere(5000, 2));
    ToolRun c = run("convert " + in.string() + " -o " + out.string() + " --leaf-triangles 300 --memory 128M");
    ASSERT_EQ(c.status, 0) << c.output;
    EXPECT_NE(c.output.find("input triangles/s"), std::string::npos);
    EXPECT_NE(c.output.find("of a 128 MiB budget"), std::string::npos) << c.output;
    ToolRun v = run("verify " + out.string() + " --mesh " + in.string() + " --samples 2000");
    EXPECT_EQ(v.status, 0) << v.output;
    EXPECT_NE(v.output.find("verify: OK"), std::string::npos) << v.output;
}

// Converts `mesh` with `catpaq convert --memory BUDGET_MIB` in a child process and expects its
// peak resident memory, as the kernel measured it (wait4), within the budget; not what the tool
// reports of itself. Returns the tool's output.
std::string expect_convert_within_budget(const Mesh& mesh, const std::string& name, uint64_t budget_mib) {
    fs::path in = scratch() / (name + ".ply"), out = scratch() / (name + ".cpq");
    write_ply(in.string(), mesh);
    ChildRun r = run_measured({std::string(CATPAQ_BINARY_DIR) + "/apps/catpaq", "convert", in.string(), "-o", out.string(),
                               "--memory", std::to_string(budget_mib) + "M"},
                              (scratch() / (name + ".txt")).string());
    EXPECT_EQ(r.status, 0) << r.output;
    EXPECT_LE(r.peak_bytes, budget_mib << 20) << "peak " << (r.peak_bytes >> 20) << " MiB\n" << r.output;
    fs::remove(in);
    fs::remove(out);
    return r.output;
}

// --memory bounds the whole process. A million triangles at 112 MiB, 10 MiB above the smallest
// budget the tool accepts with two threads. The budget binds: what is left for data after the
// per-thread reserve is a fraction of this mesh's bins and fragments, and the rest goes to
// scratch files (checked below). bench/catp/memory_budget_bench sweeps more budgets, thread
// counts and runs.
TEST(Cli, ConvertOfAMillionTrianglesStaysWithinATightMemoryBudget) {
    const std::string output = expect_convert_within_budget(make_scan_like(1000000, 7), "scan1m", 112);
    EXPECT_EQ(output.find(" 0.0 MiB of scratch data"), std::string::npos) << output;
    EXPECT_NE(output.find("MiB of scratch data written to disk"), std::string::npos) << output;
}

// Where density varies a hundredfold (a dense sphere inside a sparse blob), the largest leaves
// and diamonds, not the mean ones, set the coarsening's memory. Before the leaf level took the
// largest leaf into account, this run peaked at 158-163 MiB of its 112 MiB budget; now 92-101.
TEST(Cli, ConvertOfUnevenDensityStaysWithinItsMemoryBudget) {
    expect_convert_within_budget(make_uneven_density(1000000, 7), "uneven1m", 112);
}

// Given the wrong original (the same sphere 4 diagonals away), verify used to print the
// distances and "verify: OK"; the stored bounds must hold, and it says by how much they do not.
TEST(Cli, VerifyWithTheWrongOriginalFailsAndSaysByHowMuch) {
    fs::path in = scratch() / "right.ply", wrong = scratch() / "wrong.ply", out = scratch() / "right.cpq";
    Mesh sphere = make_sphere(3000, 2);
    write_ply(in.string(), sphere);
    double shift = 4 * sphere.bounds().diagonal();
    for (Vec3d& p : sphere.positions) p[0] += shift;
    write_ply(wrong.string(), sphere);
    ASSERT_EQ(run("convert " + in.string() + " -o " + out.string() + " --leaf-triangles 300 --quiet").status, 0);
    ToolRun good = run("verify " + out.string() + " --mesh " + in.string() + " --samples 2000");
    EXPECT_EQ(good.status, 0) << good.output;
    ToolRun bad = run("verify " + out.string() + " --mesh " + wrong.string() + " --samples 2000");
    EXPECT_EQ(bad.status, 1) << bad.output;
    EXPECT_NE(bad.output.find("exceeds the stored bound"), std::string::npos) << bad.output;
    EXPECT_NE(bad.output.find("verify: FAILED"), std::string::npos) << bad.output;
}

// Two long triangles far thinner than the grid step vanish at every level: convert says so
// (and the bounds include them, tests/catp/test_errors.cpp); a plain sphere gives no warning.
TEST(Cli, ConvertWarnsWhenThinGeometryIsLost) {
    fs::path plain = scratch() / "plain.ply", thin = scratch() / "thin.ply", out = scratch() / "thin.cpq";
    Mesh sphere = make_sphere(4000, 3);
    write_ply(plain.string(), sphere);
    sphere.normals.clear();
    sphere.colors.clear();
    uint32_t base = uint32_t(sphere.positions.size());
    sphere.positions.insert(sphere.positions.end(), {{-1, -1, -1}, {1, 1, 1}, {1, 1, 1.0001}});
    sphere.indices.insert(sphere.indices.end(), {base, base + 1, base + 2});
    write_ply(thin.string(), sphere);
    ToolRun a = run("convert " + plain.string() + " -o " + out.string() + " --quiet");
    ASSERT_EQ(a.status, 0) << a.output;
    EXPECT_EQ(a.output.find("warning"), std::string::npos) << a.output;
    ToolRun b = run("convert " + thin.string() + " -o " + out.string() + " --quiet");
    ASSERT_EQ(b.status, 0) << b.output;
    EXPECT_NE(b.output.find("warning: thin geometry is lost"), std::string::npos) << b.output;
    ToolRun v = run("verify " + out.string() + " --mesh " + thin.string() + " --samples 5000");
    EXPECT_EQ(v.status, 0) << v.output;
}

// Before, convert built the whole dataset and then failed renaming its temporary onto the
// directory, naming the temporary. Now it refuses at once, naming what the user typed.
TEST(Cli, ConvertRefusesAnExistingDirectoryAsOutputAtOnce) {
    fs::path in = scratch() / "dir_input.ply", dir = scratch() / "existing_dir";
    write_ply(in.string(), make_sphere(2000, 1));
    fs::create_directories(dir);
    ToolRun r = run("convert " + in.string() + " -o " + dir.string());
    EXPECT_EQ(r.status, 1) << r.output;
    EXPECT_NE(r.output.find("'" + dir.string() + "' is a directory"), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find(".tmp"), std::string::npos) << "names an internal temporary: " << r.output;
    EXPECT_EQ(r.output.find("input triangles/s"), std::string::npos) << "converted before refusing: " << r.output;
    EXPECT_TRUE(fs::is_empty(dir));
}

namespace {

// Starts `catpaq convert` on `input` in a child process (output and errors to a log).
pid_t start_convert(const fs::path& input, const fs::path& output, const fs::path& log) {
    pid_t pid = fork();
    if (pid == 0) {
        FILE* out = freopen(log.c_str(), "w", stdout);
        (void)out;
        dup2(fileno(stdout), fileno(stderr));
        std::string bin = std::string(CATPAQ_BINARY_DIR) + "/apps/catpaq";
        execl(bin.c_str(), bin.c_str(), "convert", input.c_str(), "-o", output.c_str(), "--threads", "1", "--quiet",
              (char*)nullptr);
        _exit(127);
    }
    return pid;
}

// Every name in `dir` that starts with `output`'s name (the output itself or a temporary).
std::vector<std::string> traces_of(const fs::path& output) {
    std::vector<std::string> out;
    for (auto& e : fs::directory_iterator(output.parent_path()))
        if (e.path().filename().string().rfind(output.filename().string(), 0) == 0) out.push_back(e.path().string());
    return out;
}

}  // namespace

// Interrupted by SIGINT, SIGTERM or SIGKILL in the middle of a conversion, convert leaves
// nothing next to its output (before: NAME.cpq.nodes.tmp.PID, after any of the three): the
// output and the node spill have no name until the output is complete.
TEST(Cli, ConvertInterruptedBySignalsLeavesNothingBehind) {
    fs::path dir = scratch() / "signals";
    fs::create_directories(dir);
    fs::path in = dir / "big.ply";
    write_ply(in.string(), make_scan_like(1000000, 3));  // about 2 s on one thread
    for (int sig : {SIGINT, SIGTERM, SIGKILL}) {
        SCOPED_TRACE(strsignal(sig));
        fs::path out = dir / "interrupted.cpq";
        pid_t pid = start_convert(in, out, dir / "log.txt");
        // Let it get well into the build (the node spill exists once the input is read), and
        // look for traces meanwhile: there must be none while it runs either.
        bool running = true;
        for (int i = 0; i < 15 && running; ++i) {
            usleep(20000);
            EXPECT_TRUE(traces_of(out).empty()) << "while running: " << traces_of(out)[0];
            running = waitpid(pid, nullptr, WNOHANG) == 0;
        }
        ASSERT_TRUE(running) << "the conversion ended before the signal: use a larger mesh";
        kill(pid, sig);
        int status = 0;
        waitpid(pid, &status, 0);
        EXPECT_TRUE(WIFSIGNALED(status)) << read_file((dir / "log.txt").string());
        EXPECT_TRUE(traces_of(out).empty()) << traces_of(out)[0];
    }
}

// What an older version or a killed run left (NAME.cpq.tmp.PID, NAME.cpq.nodes.tmp.PID of a
// process that no longer runs) is removed by the next conversion to that output.
TEST(Cli, ConvertRemovesTemporariesThatAKilledRunLeft) {
    fs::path dir = scratch() / "stale";
    fs::create_directories(dir);
    fs::path in = dir / "s.ply", out = dir / "s.cpq";
    write_ply(in.string(), make_sphere(1000, 1));
    pid_t gone = fork();
    if (gone == 0) _exit(0);
    waitpid(gone, nullptr, 0);
    fs::path stale_nodes = dir / ("s.cpq.nodes.tmp." + std::to_string(gone)), stale = dir / ("s.cpq.tmp." + std::to_string(gone));
    fs::path alive = dir / ("s.cpq.tmp." + std::to_string(getpid()));  // this process runs: kept
    write_text(stale_nodes, "left over");
    write_text(stale, "left over");
    write_text(alive, "in use");
    ToolRun r = run("convert " + in.string() + " -o " + out.string() + " --quiet");
    EXPECT_EQ(r.status, 0) << r.output;
    EXPECT_FALSE(fs::exists(stale_nodes));
    EXPECT_FALSE(fs::exists(stale));
    EXPECT_TRUE(fs::exists(alive));
    EXPECT_NE(r.output.find("left by an interrupted run"), std::string::npos) << r.output;
    fs::remove(alive);
}

TEST(Cli, MissingInputIsAClearError) {
    fs::path out = scratch() / "missing.cpq";
    expect_failure("convert " + (scratch() / "nope.ply").string() + " -o " + out.string(), "nope.ply");
    expect_nothing_written(out);
}

TEST(Cli, TruncatedPlyIsRefusedAndNothingIsWritten) {
    fs::path in = scratch() / "trunc.ply", out = scratch() / "trunc.cpq";
    write_ply(in.string(), make_sphere(2000, 1));
    fs::resize_file(in, fs::file_size(in) / 2);
    expect_failure("convert " + in.string() + " -o " + out.string(), "trunc.ply");
    expect_nothing_written(out);
}

TEST(Cli, NanCoordinatesAreRefused) {
    fs::path in = scratch() / "nan.obj", out = scratch() / "nan.cpq";
    write_text(in, "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n");
    ToolRun r = run("convert " + in.string() + " -o " + out.string());
    EXPECT_NE(r.status, 0) << r.output;
    EXPECT_NE(r.output.find("nan.obj"), std::string::npos) << r.output;
    expect_nothing_written(out);
}

TEST(Cli, EmptyMeshIsRefused) {
    fs::path in = scratch() / "empty.off", out = scratch() / "empty.cpq";
    write_text(in, "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n");
    expect_failure("convert " + in.string() + " -o " + out.string(), "empty.off");
    expect_nothing_written(out);
}

TEST(Cli, UnknownFormatIsRefused) {
    fs::path in = scratch() / "mesh.xyz123", out = scratch() / "unknown.cpq";
    write_text(in, "hello world\n");
    expect_failure("convert " + in.string() + " -o " + out.string(), "unknown mesh format");
    expect_nothing_written(out);
}

TEST(Cli, ZeroExtentModelIsRefusedWithAReason) {
    fs::path in = scratch() / "point.obj", out = scratch() / "point.cpq";
    write_text(in, "v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n");
    expect_failure("convert " + in.string() + " -o " + out.string(), "zero extent");
    expect_nothing_written(out);
}

TEST(Cli, BadOptionsAreClearErrors) {
    fs::path in = scratch() / "opt.ply", out = scratch() / "opt.cpq";
    write_ply(in.string(), make_sphere(500, 1));
    expect_failure("convert " + in.string() + " -o " + out.string() + " --leaf-triangles abc", "--leaf-triangles");
    expect_failure("convert " + in.string() + " -o " + out.string() + " --leaf-triangles 3", "outside");
    expect_failure("convert " + in.string() + " -o " + out.string() + " --bogus 1", "unknown option --bogus");
    expect_failure("convert " + in.string(), "--output is required");
    expect_failure("convert " + in.string() + " -o " + out.string() + " --format aqp", "unknown --format");
    expect_failure("convert " + in.string() + " -o /nonexistent_dir_catpaq/x.cpq", "/nonexistent_dir_catpaq");
    expect_failure("convert " + in.string() + " -o " + out.string() + " --memory 1M", "MiB for the program itself");
    expect_failure("convert " + in.string() + " -o " + out.string() + " --memory lots", "--memory");
    expect_nothing_written(out);
    expect_failure("frobnicate", "unknown command");
}

TEST(Cli, VerifyRejectsCorruptTruncatedAndForeignFiles) {
    fs::path in = scratch() / "v.ply", good = scratch() / "v.cpq";
    write_ply(in.string(), make_sphere(3000, 4));
    ASSERT_EQ(run("convert " + in.string() + " -o " + good.string() + " --leaf-triangles 300 --quiet").status, 0);
    std::string bytes = read_file(good.string());

    fs::path corrupt = scratch() / "corrupt.cpq";
    std::string flipped = bytes;
    flipped[flipped.size() - 100] ^= 0x40;  // inside the last node's payload
    write_text(corrupt, flipped);
    ToolRun r = run("verify " + corrupt.string());
    EXPECT_EQ(r.status, 1) << r.output;
    EXPECT_NE(r.output.find("checksum"), std::string::npos) << r.output;

    fs::path truncated = scratch() / "truncated.cpq";
    write_text(truncated, bytes.substr(0, bytes.size() - 10));
    expect_failure("verify " + truncated.string(), "truncated");

    fs::path header = scratch() / "header.cpq";
    std::string bad_header = bytes;
    bad_header[9] ^= 1;  // version field
    write_text(header, bad_header);
    expect_failure("verify " + header.string(), "header.cpq");

    expect_failure("verify " + in.string(), "not a catpaq dataset");
}

namespace {

// A `catpaq serve` subprocess on a free port, stopped (SIGTERM) when destroyed.
class ServerProcess {
public:
    explicit ServerProcess(const fs::path& root) {
        log_ = scratch() / ("serve_" + std::to_string(counter_++) + ".log");
        pid_ = fork();
        if (pid_ == 0) {
            FILE* out = freopen(log_.c_str(), "w", stdout);
            (void)out;
            dup2(fileno(stdout), fileno(stderr));
            std::string bin = std::string(CATPAQ_BINARY_DIR) + "/apps/catpaq";
            execl(bin.c_str(), bin.c_str(), "serve", "--root", root.c_str(), "--port", "0", (char*)nullptr);
            _exit(127);
        }
        for (int i = 0; i < 200 && url_.empty(); ++i) {
            usleep(50000);
            std::string text = read_file(log_.string());
            auto at = text.find("http://");
            if (text.find("serving") != std::string::npos && at != std::string::npos)
                url_ = text.substr(at, text.find_first_of(" \n", at) - at);
        }
    }
    ~ServerProcess() {
        if (pid_ > 0) {
            kill(pid_, SIGTERM);
            int status = 0;
            waitpid(pid_, &status, 0);
        }
    }
    const std::string& url() const { return url_; }

private:
    static inline int counter_ = 0;
    pid_t pid_ = -1;
    fs::path log_;
    std::string url_;
};

}  // namespace

TEST(Cli, RenderOverHttpFromTheServerEqualsRenderFromTheLocalFile) {
    fs::path dir = scratch() / "served";
    fs::create_directories(dir);
    fs::path dataset = dir / "bunny.cpq";
    ToolRun c = run("convert " + std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply -o " + dataset.string() + " --quiet");
    ASSERT_EQ(c.status, 0) << c.output;
    ServerProcess server(dir);
    ASSERT_FALSE(server.url().empty()) << "server did not start";
    fs::path local = scratch() / "frames_local", remote = scratch() / "frames_http";
    ToolRun a = run("render " + dataset.string() + " --orbit 3 --size 200x150 --out " + local.string());
    ASSERT_EQ(a.status, 0) << a.output;
    ToolRun b = run("render " + server.url() + "api/datasets/bunny --orbit 3 --size 200x150 --out " + remote.string() +
                    " --stats " + (remote / "stats.jsonl").string());
    ASSERT_EQ(b.status, 0) << b.output;
    for (int i = 0; i < 3; ++i) {
        char name[32];
        std::snprintf(name, sizeof name, "frame_%04d.png", i);
        std::string x = read_file((local / name).string()), y = read_file((remote / name).string());
        EXPECT_GT(x.size(), 1000u);
        EXPECT_EQ(x, y) << name << ": the HTTP render differs from the local one";
    }
    std::string stats = read_file((remote / "stats.jsonl").string());
    EXPECT_NE(stats.find("\"certified_error_px\""), std::string::npos);
    EXPECT_NE(stats.find("\"converged\":true"), std::string::npos);
}

TEST(Cli, RenderRefusesABadDatasetAndBadOptions) {
    expect_failure("render " + (scratch() / "absent.cpq").string(), "absent.cpq");
    expect_failure("render http://127.0.0.1:1/api/datasets/none --orbit 1", "127.0.0.1:1");
    fs::path in = scratch() / "r.ply", out = scratch() / "r.cpq";
    write_ply(in.string(), make_sphere(500, 1));
    ASSERT_EQ(run("convert " + in.string() + " -o " + out.string() + " --quiet").status, 0);
    expect_failure("render " + out.string() + " --size 10x10", "--size");
    expect_failure("render " + out.string() + " --background 300,0,0", "--background");
    expect_failure("render " + out.string() + " --up x", "--up");
    expect_failure("render " + out.string() + " --camera-path " + in.string(), "r.ply");
}

TEST(Cli, RenderWithATinyGpuCacheEvictsAndStillConvergesToTheSameImages) {
    fs::path dataset = scratch() / "cache_bunny.cpq";
    ASSERT_EQ(run("convert " + std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply -o " + dataset.string() + " --quiet").status, 0);
    fs::path big = scratch() / "frames_big_cache", tiny = scratch() / "frames_tiny_cache";
    ToolRun a = run("render " + dataset.string() + " --orbit 4 --size 200x150 --out " + big.string());
    ASSERT_EQ(a.status, 0) << a.output;
    // 64 KiB holds less than one view's cut: every frame evicts and re-decodes earlier nodes from
    // the compressed cache (no refetch), and must still converge to the same pixels.
    ToolRun b = run("render " + dataset.string() + " --orbit 4 --size 200x150 --gpu-cache 64K --out " + tiny.string() +
                    " --stats " + (tiny / "stats.jsonl").string());
    ASSERT_EQ(b.status, 0) << b.output;
    for (int i = 0; i < 4; ++i) {
        char name[32];
        std::snprintf(name, sizeof name, "frame_%04d.png", i);
        EXPECT_EQ(read_file((big / name).string()), read_file((tiny / name).string())) << name;
    }
    EXPECT_EQ(read_file((tiny / "stats.jsonl").string()).find("\"converged\":false"), std::string::npos);
}
