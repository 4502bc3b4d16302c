#pragma once
// The dataset describers of this build (server/describe.h), one per format it knows: CATP, AQP, points.
// `catpaq serve` gives them to the server; a format without one is served all the same.
#include "server/describe.h"

namespace catpaq {

DatasetDescribers builtin_dataset_describers();

}  // namespace catpaq
