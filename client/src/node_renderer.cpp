// GL state shared by every format's renderer (client/node_renderer.h).
#include "client/node_renderer.h"

#include <epoxy/gl.h>

#include "client/gl_program.h"

namespace catpaq {

void begin_draw(const Camera& camera, const RenderSettings& settings, bool triangles) {
    const bool gles = current_context_is_gles();
    glViewport(0, 0, camera.width, camera.height);
    if (settings.clear) {
        glClearColor(settings.background[0], settings.background[1], settings.background[2], settings.background[3]);
        if (gles)
            glClearDepthf(1.0f);
        else
            glClearDepth(1.0);  // glClearDepthf is GL 4.1
        glDepthMask(GL_TRUE);
        glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    }
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glDisable(GL_BLEND);
    if (triangles && settings.cull_back_faces) {
        glEnable(GL_CULL_FACE);
        glCullFace(GL_BACK);
        glFrontFace(GL_CCW);
    } else {
        glDisable(GL_CULL_FACE);
    }
    if (triangles && !gles) glPolygonMode(GL_FRONT_AND_BACK, settings.wireframe ? GL_LINE : GL_FILL);
}

}  // namespace catpaq
