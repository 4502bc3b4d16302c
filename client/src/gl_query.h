#pragma once
// Private: GL queries for gl_context.cpp, which includes the EGL headers (they clash with
// epoxy's GL header, so GL calls live in gl_query.cpp).
#include <string>

namespace catpaq::detail {

int current_gl_version(bool& desktop);  // e.g. 33 for 3.3, through libepoxy
std::string current_gl_string(bool renderer);  // GL_RENDERER or GL_VERSION

}  // namespace catpaq::detail
