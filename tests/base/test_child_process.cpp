#include <gtest/gtest.h>

#include <filesystem>

#include "base/child_process.h"
#include "base/error.h"
#include "scratch_directory.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

std::string log_path(const char* name) {
    static const catpaq::test::ScratchDirectory dir("catpaq_child_");
    return (dir / name).string();
}

}  // namespace

TEST(ChildProcess, ExitStatusAndBothOutputStreamsComeBackAndTheLogIsRemoved) {
    const std::string log = log_path("status.txt");
    ChildRun r = run_measured({"/bin/sh", "-c", "echo to-stdout; echo to-stderr >&2; exit 3"}, log);
    EXPECT_EQ(r.status, 3);
    EXPECT_NE(r.output.find("to-stdout"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("to-stderr"), std::string::npos) << r.output;
    EXPECT_GE(r.seconds, 0.0);
    EXPECT_FALSE(fs::exists(log));
}

TEST(ChildProcess, PeakMemoryIsTheHighWaterMarkOfTheChild) {
    // The shell holds a 64 MB string for a moment; the other child holds nothing.
    ChildRun big = run_measured({"/bin/sh", "-c", "x=$(head -c 64000000 /dev/zero | tr '\\0' a); echo ${#x}"},
                                log_path("big.txt"));
    ChildRun small = run_measured({"/bin/sh", "-c", "exit 0"}, log_path("small.txt"));
    ASSERT_EQ(big.status, 0) << big.output;
    EXPECT_NE(big.output.find("64000000"), std::string::npos) << big.output;
    EXPECT_GE(big.peak_bytes, uint64_t(64000000));
    EXPECT_LT(small.peak_bytes, uint64_t(16) << 20);
}

TEST(ChildProcess, AProgramThatCannotStartExitsWith127) {
    ChildRun r = run_measured({"/nonexistent/program"}, log_path("missing.txt"));
    EXPECT_EQ(r.status, 127);
}

TEST(ChildProcess, NoProgramIsAnError) { EXPECT_THROW(run_measured({}, log_path("none.txt")), Error); }
