// catpaq: the command-line front end. Subcommands live in their own files (apps/*.cpp) and
// register themselves in the table below; each only parses options and calls a module.
#include <cstdio>
#include <cstring>
#include <string>

#include "apps/commands.h"
#include "base/error.h"

namespace {

struct Command {
    const char* name;
    const char* summary;
    int (*run)(int argc, char** argv);
};

const Command kCommands[] = {
    {"convert", "convert a mesh into a streamable dataset", catpaq::cmd_convert},
    {"info", "print facts about a mesh file", catpaq::cmd_info},
    {"render", "render a dataset headless (streaming) to PNG frames and statistics", catpaq::cmd_render},
    {"serve", "serve datasets over HTTP (docs/http-api.md)", catpaq::cmd_serve},
    {"verify", "check a dataset's invariants and measure its error", catpaq::cmd_verify},
    {"view", "open a dataset in a desktop window (orbit, pan, zoom, fly-to)", catpaq::cmd_view},
};

void usage(FILE* out) {
    std::fprintf(out, "usage: catpaq <command> [options]\n\ncommands:\n");
    for (const Command& c : kCommands) std::fprintf(out, "  %-10s %s\n", c.name, c.summary);
    std::fprintf(out, "\nRun 'catpaq <command> --help' for the options of one command.\n");
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
        usage(argc < 2 ? stderr : stdout);
        return argc < 2 ? 2 : 0;
    }
    for (const Command& c : kCommands) {
        if (std::strcmp(argv[1], c.name) != 0) continue;
        try {
            return c.run(argc - 1, argv + 1);
        } catch (const catpaq::Error& e) {
            std::fprintf(stderr, "catpaq %s: error: %s\n", c.name, e.what());
            return 1;
        } catch (const std::bad_alloc&) {
            std::fprintf(stderr, "catpaq %s: error: out of memory\n", c.name);
            return 1;
        }
    }
    std::fprintf(stderr, "catpaq: unknown command '%s'\n\n", argv[1]);
    usage(stderr);
    return 2;
}
