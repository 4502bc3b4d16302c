// The dataset prefix every format starts from, and the registry of formats by archive kind.
#include "client/format.h"

#include "base/checksum.h"
#include "base/error.h"

namespace catpaq {

DatasetPrefix DatasetPrefix::parse(const uint8_t* data, size_t size, const std::string& source) {
    DatasetPrefix prefix;
    prefix.source = source;
    ArchiveHeader& header = prefix.header;
    std::string problem = parse_archive_header(data, size, header);
    if (problem.empty() && size < header.index_offset + header.index_size) problem = "prefix is truncated";
    if (problem.empty()) problem = parse_archive_index(header, data + header.index_offset, header.index_size, prefix.entries);
    // Formats trust their metadata: it is checked here, once, for all of them.
    if (problem.empty() && checksum64(data + header.meta_offset, header.meta_size) != header.meta_checksum)
        problem = "metadata checksum mismatch (corrupt dataset)";
    if (!problem.empty()) fail("'%s': %s", source.c_str(), problem.c_str());
    prefix.meta.assign(data + header.meta_offset, data + header.meta_offset + header.meta_size);
    return prefix;
}

void FormatRegistry::add(FormatModule module) {
    for (FormatModule& m : modules_) {
        if (m.kind == module.kind) {
            m = std::move(module);
            return;
        }
    }
    modules_.push_back(std::move(module));
}

const FormatModule* FormatRegistry::find(ArchiveKind kind) const {
    for (const FormatModule& m : modules_)
        if (m.kind == kind) return &m;
    return nullptr;
}

const FormatModule& FormatRegistry::module_for(const DatasetPrefix& prefix) const {
    const FormatModule* m = find(prefix.header.kind);
    if (!m) fail("'%s' holds a dataset of kind %s, which this program cannot stream", prefix.source.c_str(),
                 archive_kind_name(prefix.header.kind));
    return *m;
}

}  // namespace catpaq
