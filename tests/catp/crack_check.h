#pragma once
// The crack tests use the library's crack checks (catp/crack_check.h) under their old names.
#include "catp/crack_check.h"

namespace catpaq::test {

using catpaq::border_edges_off_original_border;
using catpaq::cut_topology;
using catpaq::CutTopology;
using catpaq::random_cut;

}  // namespace catpaq::test
