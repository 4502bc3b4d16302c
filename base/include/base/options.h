#pragma once
// A small command-line option parser for the catpaq subcommands: `--name value`, `--name=value`,
// boolean `--flag`, and positional arguments. Unknown options, missing values and malformed
// numbers are reported as catpaq::Error with the option's name.
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace catpaq {

class Options {
public:
    // usage: printed by --help; flags: names of options that take no value.
    Options(int argc, char** argv, std::string usage, std::vector<std::string> flags = {});

    bool help() const { return help_; }
    const std::string& usage() const { return usage_; }
    const std::vector<std::string>& positional() const { return positional_; }

    bool has(const std::string& name);
    bool flag(const std::string& name);
    std::string get(const std::string& name, const std::string& fallback);
    std::string require(const std::string& name);
    double number(const std::string& name, double fallback, double min, double max);
    int64_t integer(const std::string& name, int64_t fallback, int64_t min, int64_t max);
    // Sizes like 512M, 2G, 64k (powers of 1024); plain numbers are bytes.
    uint64_t bytes(const std::string& name, uint64_t fallback);

    // Throws Error for any option given but never asked for (call after all lookups).
    void finish();

private:
    std::string usage_;
    std::map<std::string, std::string> values_;
    std::map<std::string, bool> used_;
    std::vector<std::string> positional_;
    bool help_ = false;
};

}  // namespace catpaq
