#pragma once
// The box format's GPU side (tests only): a NodeRenderer (client/node_renderer.h) keeping one
// float vertex buffer per node, least recently used first under its budget, drawn in one colour.
// Needs a current GL context.
#include <memory>

#include "box_format.h"
#include "client/node_renderer.h"

namespace catpaq::test {

std::unique_ptr<NodeRenderer> create_box_renderer(const DatasetFormat& format);

// box_format_module() with its renderer: what a streaming session registers.
FormatModule box_format_module_with_renderer();

// The colour the box renderer draws (RGB, 0..255).
constexpr uint8_t kBoxColor[3] = {200, 80, 40};

}  // namespace catpaq::test
