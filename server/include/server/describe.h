#pragma once
// What the server's catalog says about a dataset beyond its container (header, index, levels):
// its world bounds and its format's decoded metadata. The server core serves every archive kind
// the same way (prefix, nodes by key, raw ranges): it knows no format. A describer per archive
// kind, given in ServerSettings::describers, adds the format's part of the catalog; a dataset of
// a kind without one is served all the same, its catalog entry without bounds or details.
// `catpaq serve` uses this build's describers (server_formats/describers.h).
#include <array>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "common_codec/archive.h"

namespace catpaq {

struct DatasetDescription {
    bool has_bounds = false;  // the world bounds below are known (catalog and details: "bounds")
    std::array<double, 3> bounds_min{0, 0, 0}, bounds_max{0, 0, 0};
    // A JSON object of the format's metadata, served in the details under the format's name
    // (archive_kind_name: "catp"); empty: none.
    std::string details_json;
};

// Describes a dataset from its header and metadata bytes. Returns an empty string, or the problem
// (the dataset is then served without a description, with "meta_error" saying why). Called once
// per dataset at startup.
using DatasetDescriber =
    std::function<std::string(const ArchiveHeader& header, const std::vector<uint8_t>& meta, DatasetDescription& out)>;
using DatasetDescribers = std::map<ArchiveKind, DatasetDescriber>;

}  // namespace catpaq
