#pragma once
// The datasets a server instance serves: every *.cpq file under the root, opened (and so
// validated) once at startup through ArchiveReader, which memory-maps it. Immutable after
// scan(), so the I/O threads read it without locks.
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "common_codec/archive.h"
#include "log.h"
#include "server/describe.h"

namespace catpaq::serve {

struct Dataset {
    std::string name;       // path relative to the root without ".cpq", '/'-separated
    std::string file;       // path relative to the root, with the extension (the /files/ route)
    std::string real_path;  // resolved path (inside the real root)
    std::unique_ptr<ArchiveReader> reader;
    std::unordered_map<uint64_t, uint32_t> by_key;  // node key -> entry index (first in index order)
    uint64_t payload_bytes = 0;
    std::string etag;         // "\"<header checksum>\"": identifies the file's content
    std::string prefix_etag;  // "\"<header checksum>-first\""
    uint64_t first_request_size = 0;  // the /prefix route's bytes (archive_first_request_size)
    bool has_bounds = false;  // from the describer of its kind
    double bounds_min[3] = {0, 0, 0}, bounds_max[3] = {0, 0, 0};
    std::string details_json;  // GET /api/datasets/{name}
};

class Registry {
public:
    // Scans `root` recursively. Files that are not valid datasets, symlinks resolving outside the
    // real root and names that cannot be served are logged (warn) and skipped. Each dataset is
    // described by the describer of its kind, if any. Throws Error if the root is not a readable
    // directory.
    void scan(const std::string& root, const DatasetDescribers& describers, const Logger& log);

    const Dataset* by_name(std::string_view name) const;
    const Dataset* by_file(std::string_view file) const;
    const std::vector<std::unique_ptr<Dataset>>& datasets() const { return datasets_; }
    const std::string& catalog_json() const { return catalog_json_; }
    const std::string& real_root() const { return real_root_; }

private:
    void add(const std::string& relative, const std::string& real_path, const DatasetDescribers& describers,
             const Logger& log);

    std::string real_root_;
    std::vector<std::unique_ptr<Dataset>> datasets_;  // sorted by name
    std::map<std::string, const Dataset*, std::less<>> by_name_, by_file_;
    std::string catalog_json_;
};

}  // namespace catpaq::serve
