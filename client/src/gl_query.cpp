#include "gl_query.h"

#include <epoxy/gl.h>

namespace catpaq::detail {

int current_gl_version(bool& desktop) {
    desktop = epoxy_is_desktop_gl();
    return epoxy_gl_version();
}

std::string current_gl_string(bool renderer) {
    const GLubyte* s = glGetString(renderer ? GL_RENDERER : GL_VERSION);
    return s ? reinterpret_cast<const char*>(s) : "";
}

}  // namespace catpaq::detail
