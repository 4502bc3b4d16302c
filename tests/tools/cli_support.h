#pragma once
// Running the catpaq tool as a subprocess in the CLI tests: its output and exit status, a scratch
// directory per test process, and the checks every refusal shares.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <sys/wait.h>
#include <unistd.h>

#include "scratch_directory.h"

namespace catpaq::cli_test {

namespace fs = std::filesystem;

struct ToolRun {
    int status = -1;
    std::string output;  // stdout and stderr
};

inline fs::path scratch() {
    static const test::ScratchDirectory dir("catpaq_cli_");
    return dir.path();
}

// Runs the tool with `args`; its stdout and stderr together, or with `stdout_only` its stdout
// alone (stderr goes to the test's: for --json reports).
inline ToolRun run(const std::string& args, bool stdout_only = false) {
    std::string command = std::string(CATPAQ_BINARY_DIR) + "/apps/catpaq " + args + (stdout_only ? "" : " 2>&1");
    ToolRun r;
    FILE* pipe = popen(command.c_str(), "r");
    char buffer[4096];
    size_t n;
    while ((n = fread(buffer, 1, sizeof buffer, pipe)) > 0) r.output.append(buffer, n);
    int status = pclose(pipe);
    r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}

inline void write_text(const fs::path& path, const std::string& text) { std::ofstream(path) << text; }

// No output and no temporary left next to it.
inline void expect_nothing_written(const fs::path& output) {
    EXPECT_FALSE(fs::exists(output)) << output;
    for (auto& e : fs::directory_iterator(output.parent_path()))
        EXPECT_EQ(e.path().filename().string().find(output.filename().string() + "."), std::string::npos) << e.path();
}

inline void expect_failure(const std::string& args, const std::string& message_part) {
    ToolRun r = run(args);
    EXPECT_NE(r.status, 0) << args << "\n" << r.output;
    EXPECT_NE(r.output.find(message_part), std::string::npos) << "expected '" << message_part << "' in:\n" << r.output;
}


}  // namespace catpaq::cli_test
