// The setup script installs what a command needs and never touches the machine's services: it
// used to stop any running nginx (`systemctl disable --now nginx`, `pkill -x nginx`) and
// installed the benchmark's tools (wrk, nginx) for the demo too.
#include <gtest/gtest.h>

#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>

namespace {

std::string read_text(const std::string& relative) {
    std::ifstream in(std::string(CATPAQ_SOURCE_DIR) + "/" + relative);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

// The package names of a list (comments and blank lines skipped).
std::set<std::string> packages(const std::string& relative) {
    std::set<std::string> out;
    std::istringstream in(read_text(relative));
    for (std::string line; std::getline(in, line);) {
        line = line.substr(0, line.find('#'));
        std::istringstream words(line);
        for (std::string w; words >> w;) out.insert(w);
    }
    return out;
}

}  // namespace

TEST(Scripts, SetupNeverStopsDisablesOrKillsServices) {
    std::string setup = read_text("scripts/setup.sh");
    ASSERT_FALSE(setup.empty());
    // Commands only (comments may say what the script does not do).
    std::string code;
    std::istringstream in(setup);
    for (std::string line; std::getline(in, line);)
        if (line.find_first_not_of(" \t") == std::string::npos || line[line.find_first_not_of(" \t")] != '#')
            code += line + "\n";
    for (const char* word : {"systemctl", "pkill", "killall", "service ", "kill "})
        EXPECT_EQ(code.find(word), std::string::npos) << "setup.sh runs '" << word << "'";
}

TEST(Scripts, TheDemoInstallsNoTestOrBenchmarkTools) {
    std::set<std::string> demo = packages("scripts/packages.txt"), test = packages("scripts/packages-test.txt"),
                          bench = packages("scripts/packages-bench.txt");
    ASSERT_FALSE(demo.empty());
    for (const char* tool : {"wrk", "nginx-light", "nginx", "xvfb", "libgtest-dev", "libbenchmark-dev"})
        EXPECT_EQ(demo.count(tool), 0u) << tool << " is installed for the demo";
    EXPECT_EQ(bench.count("wrk") + bench.count("nginx-light"), 2u);
    EXPECT_EQ(test.count("wrk") + test.count("nginx-light"), 0u) << "the tests do not run the server benchmark";
    // scripts/test.sh asks for the test list; demo.sh for the demo's only.
    EXPECT_NE(read_text("scripts/test.sh").find("setup.sh\" --tests"), std::string::npos);
    EXPECT_EQ(read_text("scripts/demo.sh").find("--tests"), std::string::npos);
}
