// catpaq view: open a dataset (local path or URL) in a desktop window with streaming, orbit, pan,
// zoom, fly-to on a picked point, measuring and a statistics overlay (client/viewer.h).
#include <cstdio>
#include <string>

#include "apps/commands.h"
#include "base/error.h"
#include "base/options.h"
#include "base/output_path.h"
#include "client/viewer.h"

namespace catpaq {

static const char* kViewUsage =
    "usage: catpaq view DATASET [options]\n"
    "  DATASET is a local .cpq file, a server URL (http://HOST:PORT/api/datasets/NAME) or the URL\n"
    "  of a .cpq file on any static web server. Needs a display (X11); without one use\n"
    "  `catpaq render`.\n"
    "options:\n"
    "  --size WxH             window size (default 1280x800)\n"
    "  --tolerance PX         screen-space error tolerance in pixels (default 1.5)\n"
    "  --up y|z               the model's up axis for the initial camera (default: the dataset's,\n"
    "                         recorded by convert --up; z for datasets that record none)\n"
    "  --msaa N               anti-aliasing samples per pixel (0, 2, 4, 8; default 4)\n"
    "  --frames N             draw N frames (every one, as fast as possible), then exit (for tests)\n"
    "  --exit-after SECONDS   run as usual (drawing on demand), then exit (for tests)\n"
    "  --splats round|oriented  point datasets: screen-aligned discs (default) or oriented ellipses\n"
    "  --screenshot FILE.png  save the last frame (without the overlay); exits after --frames\n"
    "                         frames or --exit-after seconds, else after 120 frames\n"
    "  --measure \"X,Y X,Y [X,Y]\"  scripted measure clicks at window pixels once the view has\n"
    "                         settled: prints the distance (2) or angle (3) on stdout, then exits\n"
    "                         (unless --exit-after); exit status 1 if a click hits nothing\n"
    "controls:\n"
    "  left drag: orbit   right or shift+left drag: pan   wheel: zoom\n"
    "  double click: fly to the point under the cursor   H: overlay\n"
    "  M: measure mode: click 2 points for their distance (and dx dy dz), a 3rd for the angle at\n"
    "  the 2nd; each result is also printed on stdout   Escape: clear the measurement, else quit\n"
    "  P or F12: screenshot, saved as catpaq_view_NNNN.png in the working directory (the first\n"
    "  free number: earlier screenshots are never overwritten)\n"
    "The window is redrawn only when something changes. Nodes that cannot be loaded are shown in\n"
    "the overlay (and on stderr); the coarser data stays on screen.\n";

static void parse_view_size(const std::string& text, int& w, int& h) {
    if (std::sscanf(text.c_str(), "%dx%d", &w, &h) != 2 || w < 16 || h < 16 || w > 16384 || h > 16384)
        usage_error("--size: '%s' is not WIDTHxHEIGHT between 16 and 16384", text.c_str());
}

int cmd_view(int argc, char** argv) {
    Options options(argc, argv, kViewUsage);
    if (options.help()) {
        std::printf("%s", kViewUsage);
        return 0;
    }
    if (options.positional().size() != 1) usage_error("expected one dataset");
    ViewerSettings settings;
    settings.location = options.positional()[0];
    if (options.has("size")) parse_view_size(options.get("size", ""), settings.width, settings.height);
    settings.session.tolerance_px = options.number("tolerance", 1.5, 0.05, 1000);
    std::string up = options.get("up", "");
    if (up == "y" || up == "Y") settings.up_axis = 1;
    else if (up == "z" || up == "Z") settings.up_axis = 2;
    else if (!up.empty()) usage_error("--up: '%s' is not y or z", up.c_str());
    settings.frames = int(options.integer("frames", 0, 1, 1 << 30));
    settings.exit_after = options.number("exit-after", 0, 0.01, 1e9);
    settings.msaa = int(options.integer("msaa", 4, 0, 64));
    settings.screenshot = options.get("screenshot", "");
    const std::string splats = options.get("splats", "round");
    if (splats == "oriented") settings.splats = SplatShape::Oriented;
    else if (splats != "round") usage_error("--splats: '%s' is not round or oriented", splats.c_str());
    const bool measure_given = options.has("measure");
    const std::string measure = options.get("measure", "");
    options.finish();
    if (settings.screenshot.size()) check_output_file(settings.screenshot, "--screenshot");
    if (measure_given) {
        settings.measure_picks = parse_pixel_picks(measure);
        settings.exit_after_measure = settings.exit_after == 0;
        // An upper bound for a view that never settles: the picks are then made on the last frame.
        if (settings.frames == 0 && settings.exit_after == 0) settings.frames = 600;
    }
    if (settings.screenshot.size() && settings.frames == 0 && settings.exit_after == 0) settings.frames = 120;
    if (settings.frames > 0) settings.vsync = false;  // scripted runs go as fast as they can

    try {
        DesktopViewer viewer(settings);
        return viewer.run();
    } catch (const NoDisplayError& e) {
        std::fprintf(stderr, "catpaq view: %s\n", e.what());
        return 1;
    }
}

}  // namespace catpaq
