// catpaq serve --root DIR: serves every dataset (*.cpq) under DIR over HTTP/1.1 until SIGINT or
// SIGTERM. Routes: docs/http-api.md.
#include <cstdio>

#include "apps/commands.h"
#include "base/error.h"
#include "base/options.h"
#include "server/server.h"
#include "server_formats/describers.h"

namespace catpaq {

int cmd_serve(int argc, char** argv) {
    Options options(argc, argv,
                    "usage: catpaq serve --root DIR [options]\n"
                    "  Serves every dataset (*.cpq, subdirectories included) under DIR over HTTP/1.1.\n"
                    "  A dataset's name is its path below DIR without the extension. Routes: docs/http-api.md.\n"
                    "options:\n"
                    "  --root DIR            dataset directory (required)\n"
                    "  --port N              TCP port (default 8080; 0 picks a free port)\n"
                    "  --bind ADDR           address to listen on (default 127.0.0.1; 0.0.0.0 for all)\n"
                    "  --threads N           I/O threads (default: one per core)\n"
                    "  --max-connections N   open connections before new ones get 503 (default 512)\n"
                    "  --timeout SECONDS     time a client has to send a request or accept data (default 10)\n"
                    "  --log-level LEVEL     error, warn, info (one line per request) or debug (default info)\n"
                    "Prints 'serving N datasets on http://ADDR:PORT/' when ready; SIGINT/SIGTERM stop it\n"
                    "gracefully.\n");
    if (options.help()) {
        std::printf("%s", options.usage().c_str());
        return 0;
    }
    ServerSettings settings;
    settings.describers = builtin_dataset_describers();
    settings.root = options.require("root");
    settings.port = uint16_t(options.integer("port", 8080, 0, 65535));
    settings.bind = options.get("bind", "127.0.0.1");
    settings.threads = int(options.integer("threads", 0, 0, 256));
    settings.max_connections = int(options.integer("max-connections", 512, 1, 1000000));
    settings.timeout_seconds = options.number("timeout", 10.0, 0.001, 86400.0);
    try {
        settings.log_level = parse_log_level(options.get("log-level", "info"));
    } catch (const Error& e) {
        usage_error("--log-level: %s", e.what());
    }
    options.finish();
    if (!options.positional().empty())
        usage_error("unexpected argument '%s': serve takes options only", options.positional()[0].c_str());
    return run_server(settings);
}

}  // namespace catpaq
