#pragma once
// The catpaq tool run from the client tests (the viewer under Xvfb, view --measure): its path
// and a shell command's exit status and combined output.
#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace catpaq::client_test {

inline std::string catpaq_binary() { return std::string(CATPAQ_BINARY_DIR) + "/apps/catpaq"; }

// Runs a shell command; returns its exit status (or -1) and its combined output.
inline int run(const std::string& command, std::string& output) {
    output.clear();
    FILE* p = popen((command + " 2>&1").c_str(), "r");
    if (!p) return -1;
    char buf[4096];
    size_t n;
    while ((n = fread(buf, 1, sizeof buf, p)) > 0) output.append(buf, n);
    int status = pclose(p);
    if (status == -1 || !WIFEXITED(status)) return -1;
    return WEXITSTATUS(status);
}

}  // namespace catpaq::client_test
