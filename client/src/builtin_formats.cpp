// The list of format modules of this build: the one place a new format is registered.
#include "client/builtin_formats.h"

#include "catp_client/catp_format.h"
#include "catp_client/catp_gpu.h"

namespace catpaq {

const FormatRegistry& builtin_formats() {
    static const FormatRegistry registry = [] {
        FormatRegistry r;
        r.add(FormatModule{ArchiveKind::Catp,
                           [](const DatasetPrefix& prefix) { return std::make_unique<CatpFormat>(prefix); },
                           create_catp_renderer});
        return r;
    }();
    return registry;
}

}  // namespace catpaq
