#include "base/options.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>

#include "base/error.h"

namespace catpaq {

// Levenshtein distance.
static size_t edit_distance(const std::string& a, const std::string& b) {
    std::vector<size_t> row(b.size() + 1);
    for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (size_t i = 1; i <= a.size(); ++i) {
        size_t diagonal = row[0];
        row[0] = i;
        for (size_t j = 1; j <= b.size(); ++j) {
            size_t up = row[j];
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
            diagonal = up;
        }
    }
    return row[b.size()];
}

std::string closest_match(const std::string& word, const std::vector<std::string>& candidates) {
    std::string best;
    size_t best_distance = std::min<size_t>(3, std::max<size_t>(1, word.size() / 3)) + 1;
    for (const std::string& c : candidates) {
        size_t d = edit_distance(word, c);
        // A prefix of a longer name (--tol for --tolerance) is a likely abbreviation too.
        if (word.size() >= 3 && c.compare(0, word.size(), word) == 0) d = std::min<size_t>(d, 1);
        if (d < best_distance) {
            best_distance = d;
            best = c;
        }
    }
    return best;
}

Options::Options(int argc, char** argv, std::string usage, std::vector<std::string> flags)
    : usage_(std::move(usage)) {
    known_.insert(flags.begin(), flags.end());
    for (int i = 1; i < argc; ++i) {
        std::string arg = argv[i];
        if (arg == "--help" || arg == "-h") {
            help_ = true;
            continue;
        }
        if (arg.size() > 2 && arg.compare(0, 2, "--") == 0) {
            std::string name = arg.substr(2), value;
            auto eq = name.find('=');
            if (eq != std::string::npos) {
                value = name.substr(eq + 1);
                name = name.substr(0, eq);
            } else if (std::find(flags.begin(), flags.end(), name) != flags.end()) {
                value = "1";
            } else {
                if (i + 1 >= argc) usage_error("option --%s needs a value", name.c_str());
                value = argv[++i];
            }
            values_[name] = value;
            used_[name] = false;
        } else {
            positional_.push_back(arg);
        }
    }
}

bool Options::has(const std::string& name) {
    known_.insert(name);
    auto it = values_.find(name);
    if (it == values_.end()) return false;
    used_[name] = true;
    return true;
}

bool Options::flag(const std::string& name) {
    if (!has(name)) return false;
    const std::string& v = values_[name];
    if (v == "1" || v == "true" || v == "yes" || v == "on") return true;
    if (v == "0" || v == "false" || v == "no" || v == "off") return false;
    usage_error("option --%s takes no value (or true/false), got '%s'", name.c_str(), v.c_str());
}

std::string Options::get(const std::string& name, const std::string& fallback) {
    return has(name) ? values_[name] : fallback;
}

std::string Options::require(const std::string& name) {
    if (!has(name)) usage_error("option --%s is required", name.c_str());
    return values_[name];
}

double Options::number(const std::string& name, double fallback, double min, double max) {
    if (!has(name)) return fallback;
    const std::string& text = values_[name];
    char* end = nullptr;
    errno = 0;
    double v = std::strtod(text.c_str(), &end);
    if (text.empty() || *end != 0 || errno != 0 || !std::isfinite(v))
        usage_error("option --%s: '%s' is not a number", name.c_str(), text.c_str());
    if (v < min || v > max) usage_error("option --%s: %s is outside [%g, %g]", name.c_str(), text.c_str(), min, max);
    return v;
}

int64_t Options::integer(const std::string& name, int64_t fallback, int64_t min, int64_t max) {
    if (!has(name)) return fallback;
    const std::string& text = values_[name];
    char* end = nullptr;
    errno = 0;
    long long v = std::strtoll(text.c_str(), &end, 10);
    if (text.empty() || *end != 0 || errno != 0)
        usage_error("option --%s: '%s' is not an integer", name.c_str(), text.c_str());
    if (v < min || v > max)
        usage_error("option --%s: %s is outside [%lld, %lld]", name.c_str(), text.c_str(), (long long)min,
                    (long long)max);
    return v;
}

uint64_t Options::bytes(const std::string& name, uint64_t fallback) {
    if (!has(name)) return fallback;
    return parse_size(values_[name], "option --" + name);
}

uint64_t parse_size(const std::string& given, const std::string& what) {
    std::string text = given;
    uint64_t scale = 1;
    if (!text.empty()) {
        char unit = char(std::toupper((unsigned char)text.back()));
        if (unit == 'K') scale = 1ull << 10;
        if (unit == 'M') scale = 1ull << 20;
        if (unit == 'G') scale = 1ull << 30;
        if (unit == 'T') scale = 1ull << 40;
        if (scale != 1) text.pop_back();
    }
    char* end = nullptr;
    errno = 0;
    double v = std::strtod(text.c_str(), &end);
    if (text.empty() || *end != 0 || errno != 0 || !(v > 0) || !std::isfinite(v))
        usage_error("%s: '%s' is not a size (like 512M or 2G)", what.c_str(), given.c_str());
    return uint64_t(v * double(scale));
}

void Options::finish() {
    std::vector<std::string> known(known_.begin(), known_.end());
    known.push_back("help");
    for (auto& [name, used] : used_) {
        if (used) continue;
        std::string guess = closest_match(name, known);
        if (guess.empty()) usage_error("unknown option --%s", name.c_str());
        usage_error("unknown option --%s; did you mean --%s?", name.c_str(), guess.c_str());
    }
}

}  // namespace catpaq
