#include "datasets.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <sys/stat.h>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "http.h"

namespace catpaq::serve {

namespace fs = std::filesystem;
using nlohmann::json;

static constexpr std::string_view kExtension = ".cpq";

static bool real_path(const std::string& path, std::string& out) {
    char buffer[PATH_MAX];
    if (!::realpath(path.c_str(), buffer)) return false;
    out = buffer;
    return true;
}

static json urls_json(const Dataset& d) {
    std::string base = "/api/datasets/" + http::encode_path(d.name);
    return json{{"details", base},
                {"prefix", base + "/prefix"},
                {"nodes", base + "/nodes/{key}"},
                {"file", "/files/" + http::encode_path(d.file)}};
}

static json bounds_json(const Dataset& d) {
    return json{{"min", {d.bounds_min[0], d.bounds_min[1], d.bounds_min[2]}},
                {"max", {d.bounds_max[0], d.bounds_max[1], d.bounds_max[2]}}};
}

static std::string dump(const json& j) { return j.dump(-1, ' ', false, json::error_handler_t::replace); }

// The format's part of a dataset's details: bounds and the decoded metadata under the format's
// name. A describer that fails (or throws) leaves the dataset served without them.
static void describe(Dataset& d, const DatasetDescriber& describer, json& details, const Logger& log) {
    const ArchiveHeader& h = d.reader->header();
    DatasetDescription description;
    std::string problem;
    try {
        problem = describer(h, d.reader->meta(), description);
    } catch (const std::exception& e) {
        problem = e.what();
    }
    json format_details;
    if (problem.empty() && !description.details_json.empty()) {
        format_details = json::parse(description.details_json, nullptr, false);
        if (!format_details.is_object()) problem = "its description is not a JSON object";
    }
    if (!problem.empty()) {
        std::string format = archive_kind_name(h.kind);
        for (char& c : format) c = char(std::toupper(uint8_t(c)));
        log.logf(LogLevel::Warn, "dataset '%s': cannot decode its %s metadata (%s); serving it without bounds",
                 d.name.c_str(), format.c_str(), problem.c_str());
        details["meta_error"] = problem;
        return;
    }
    if (description.has_bounds) {
        d.has_bounds = true;
        std::copy(description.bounds_min.begin(), description.bounds_min.end(), d.bounds_min);
        std::copy(description.bounds_max.begin(), description.bounds_max.end(), d.bounds_max);
        details["bounds"] = bounds_json(d);
    }
    if (format_details.is_object()) details[archive_kind_name(h.kind)] = std::move(format_details);
}

void Registry::scan(const std::string& root, const DatasetDescribers& describers, const Logger& log) {
    if (root.empty()) fail("no dataset root given");
    if (!real_path(root, real_root_)) fail("dataset root '%s': %s", root.c_str(), std::strerror(errno));
    struct stat st{};
    if (::stat(real_root_.c_str(), &st) != 0 || !S_ISDIR(st.st_mode))
        fail("dataset root '%s' is not a directory", root.c_str());

    std::error_code ec;
    fs::recursive_directory_iterator it(real_root_, fs::directory_options::skip_permission_denied, ec), end;
    if (ec) fail("cannot list dataset root '%s': %s", root.c_str(), ec.message().c_str());
    std::vector<std::string> found;
    for (; it != end; it.increment(ec)) {
        if (ec) {
            log.logf(LogLevel::Warn, "while scanning '%s': %s", root.c_str(), ec.message().c_str());
            ec.clear();
            continue;
        }
        const fs::path& path = it->path();
        std::string file_name = path.filename().string();
        if (file_name.size() <= kExtension.size() ||
            file_name.compare(file_name.size() - kExtension.size(), kExtension.size(), kExtension) != 0)
            continue;
        std::error_code type_ec;
        bool is_file = it->is_regular_file(type_ec);  // follows symlinks
        if (!is_file && !it->is_symlink(type_ec)) continue;
        std::string relative = path.lexically_relative(real_root_).generic_string();
        found.push_back(relative);
    }
    std::sort(found.begin(), found.end());
    for (const std::string& relative : found) {
        std::string resolved;
        if (!real_path(real_root_ + "/" + relative, resolved)) {
            log.logf(LogLevel::Warn, "skipping dataset '%s': %s", relative.c_str(), std::strerror(errno));
            continue;
        }
        if (resolved.compare(0, real_root_.size() + 1, real_root_ + "/") != 0) {
            log.logf(LogLevel::Warn, "skipping dataset '%s': it resolves to '%s', outside the root '%s'",
                     relative.c_str(), resolved.c_str(), real_root_.c_str());
            continue;
        }
        add(relative, resolved, describers, log);
    }

    json catalog = json::array();
    for (const auto& d : datasets_) {
        const ArchiveHeader& h = d->reader->header();
        json entry{{"name", d->name},
                   {"kind", archive_kind_name(h.kind)},
                   {"file_size", d->reader->size()},
                   {"node_count", h.node_count},
                   {"urls", urls_json(*d)}};
        if (d->has_bounds) entry["bounds"] = bounds_json(*d);
        catalog.push_back(std::move(entry));
    }
    catalog_json_ = dump(json{{"datasets", std::move(catalog)}});
}

void Registry::add(const std::string& relative, const std::string& resolved, const DatasetDescribers& describers,
                   const Logger& log) {
    for (char c : relative) {
        if (uint8_t(c) < 0x20 || uint8_t(c) == 0x7f || c == '\\') {
            log.logf(LogLevel::Warn, "skipping dataset '%s': its path has a control byte or a backslash",
                     http::printable(relative).c_str());
            return;
        }
    }
    auto d = std::make_unique<Dataset>();
    d->file = relative;
    d->name = relative.substr(0, relative.size() - kExtension.size());
    d->real_path = resolved;
    try {
        d->reader = std::make_unique<ArchiveReader>(resolved);
    } catch (const Error& e) {
        log.logf(LogLevel::Warn, "skipping dataset '%s': %s", d->name.c_str(), e.what());
        return;
    } catch (const std::exception& e) {
        log.logf(LogLevel::Warn, "skipping dataset '%s': %s", d->name.c_str(), e.what());
        return;
    }
    const ArchiveReader& r = *d->reader;
    const ArchiveHeader& h = r.header();
    const auto& entries = r.entries();
    d->by_key.reserve(entries.size());
    std::map<uint16_t, std::pair<uint64_t, uint64_t>> levels;  // level -> (nodes, bytes)
    for (size_t i = 0; i < entries.size(); ++i) {
        d->by_key.emplace(entries[i].key, uint32_t(i));  // keeps the first, like ArchiveReader::find
        d->payload_bytes += entries[i].size;
        auto& level = levels[entries[i].level];
        level.first += 1;
        level.second += entries[i].size;
    }
    // The stored header checksum covers the meta and index checksums, and the index holds every
    // node's checksum: it identifies the whole file's content.
    uint64_t header_checksum = 0;
    for (int i = 0; i < 8; ++i) header_checksum |= uint64_t(r.data()[kArchiveHeaderSize - 8 + i]) << (8 * i);
    d->etag = "\"" + http::hex64(header_checksum) + "\"";
    // ("-first": the route once served the prefix alone, under "-prefix"; a cache that kept that
    // body must not be told it is still current.)
    d->prefix_etag = "\"" + http::hex64(header_checksum) + "-first\"";
    d->first_request_size = archive_first_request_size(h, entries);

    json details{{"name", d->name},
                 {"kind", archive_kind_name(h.kind)},
                 {"file", d->file},
                 {"file_size", r.size()},
                 {"version", h.version},
                 {"meta_offset", h.meta_offset},
                 {"meta_size", h.meta_size},
                 {"index_offset", h.index_offset},
                 {"index_size", h.index_size},
                 {"meta_checksum", http::hex64(h.meta_checksum)},
                 {"index_checksum", http::hex64(h.index_checksum)},
                 {"node_count", h.node_count},
                 {"prefix_size", r.prefix_size()},
                 {"first_request_size", d->first_request_size},
                 {"payload_bytes", d->payload_bytes},
                 {"etag", d->etag}};
    json level_list = json::array();
    for (const auto& [level, counts] : levels)
        level_list.push_back(json{{"level", level}, {"nodes", counts.first}, {"bytes", counts.second}});
    details["levels"] = std::move(level_list);
    if (auto describer = describers.find(h.kind); describer != describers.end()) describe(*d, describer->second, details, log);
    details["urls"] = urls_json(*d);
    d->details_json = dump(details);
    log.logf(LogLevel::Info, "dataset '%s': %s, %u nodes, %llu bytes", d->name.c_str(), archive_kind_name(h.kind),
             h.node_count, (unsigned long long)r.size());

    by_name_[d->name] = d.get();
    by_file_[d->file] = d.get();
    datasets_.push_back(std::move(d));
}

const Dataset* Registry::by_name(std::string_view name) const {
    auto it = by_name_.find(name);
    return it == by_name_.end() ? nullptr : it->second;
}

const Dataset* Registry::by_file(std::string_view file) const {
    auto it = by_file_.find(file);
    return it == by_file_.end() ? nullptr : it->second;
}

}  // namespace catpaq::serve
