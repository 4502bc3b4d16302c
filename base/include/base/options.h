#pragma once
// A small command-line option parser for the catpaq subcommands: `--name value`, `--name=value`,
// boolean `--flag`, and positional arguments. Unknown options, missing values and malformed
// numbers are reported as catpaq::UsageError with the option's name; an unknown option that is
// close to one the command knows gets a "did you mean" (every option looked up counts as known).
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace catpaq {

// The candidate closest to `word` by edit distance, if it is close enough to be a likely typo
// (at most a third of the word's length, and at most 3 edits); else an empty string.
std::string closest_match(const std::string& word, const std::vector<std::string>& candidates);

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

    // Throws UsageError for any option given but never asked for (call after all lookups).
    void finish();

private:
    std::string usage_;
    std::map<std::string, std::string> values_;
    std::map<std::string, bool> used_;
    std::set<std::string> known_;  // every name looked up, given or not
    std::vector<std::string> positional_;
    bool help_ = false;
};

// A size like 512M or 2G (K, M, G, T: powers of 1024; a plain number is bytes). Throws
// UsageError naming `what` if `text` is not one.
uint64_t parse_size(const std::string& text, const std::string& what);

}  // namespace catpaq
