// The list of format modules of this build: the one place a new format is registered.
#include "client/builtin_formats.h"

#include "aqp_client/aqp_format.h"
#include "aqp_client/aqp_gpu.h"
#include "catp_client/catp_format.h"
#include "catp_client/catp_gpu.h"
#include "points_client/points_format.h"
#include "points_client/points_gpu.h"

namespace catpaq {

const FormatRegistry& builtin_formats() {
    static const FormatRegistry registry = [] {
        FormatRegistry r;
        r.add(FormatModule{ArchiveKind::Catp,
                           [](const DatasetPrefix& prefix) { return std::make_unique<CatpFormat>(prefix); },
                           create_catp_renderer});
        r.add(FormatModule{ArchiveKind::Aqp, [](const DatasetPrefix& prefix) { return std::make_unique<AqpFormat>(prefix); },
                           create_aqp_renderer});
        r.add(FormatModule{ArchiveKind::Points,
                           [](const DatasetPrefix& prefix) { return std::make_unique<PointsFormat>(prefix); },
                           create_points_renderer});
        return r;
    }();
    return registry;
}

}  // namespace catpaq
