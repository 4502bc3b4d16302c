#pragma once
// The dataset formats this build streams (client/format.h): CATP now; AQP and point clouds
// register here when they land. A session (SessionSettings::formats) or a test may use another
// registry instead.
#include "client/format.h"

namespace catpaq {

const FormatRegistry& builtin_formats();

}  // namespace catpaq
