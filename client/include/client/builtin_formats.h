#pragma once
// The dataset formats this build streams (client/format.h): CATP, AQP and points, registered in
// client/src/builtin_formats.cpp. A session (SessionSettings::formats) or a test may use another
// registry instead.
#include "client/format.h"

namespace catpaq {

const FormatRegistry& builtin_formats();

}  // namespace catpaq
