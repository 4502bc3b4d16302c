// catpaq: the command-line front end. Subcommands live in their own files (apps/*.cpp) and
// register themselves in the table below; each only parses options and calls a module.
//
// Exit status, for every command: 0 done, 1 the work failed (a bad input file, a network error,
// a failed check), 2 the command line is wrong (an unknown command or option, a malformed or
// out-of-range value, a missing or extra argument).
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

#include "apps/commands.h"
#include "base/error.h"
#include "base/options.h"
#include "common_codec/archive.h"

#ifndef CATPAQ_VERSION
#define CATPAQ_VERSION "unknown"
#endif

namespace {

struct Command {
    const char* name;
    const char* summary;
    int (*run)(int argc, char** argv);
};

const Command kCommands[] = {
    {"convert", "convert a mesh into a streamable dataset", catpaq::cmd_convert},
    {"info", "print facts about a mesh file or a dataset (local or URL)", catpaq::cmd_info},
    {"render", "render a dataset headless (streaming) to PNG frames and statistics", catpaq::cmd_render},
    {"serve", "serve datasets over HTTP (docs/http-api.md)", catpaq::cmd_serve},
    {"verify", "check a dataset's invariants and measure its error", catpaq::cmd_verify},
    {"view", "open a dataset in a desktop window (orbit, pan, zoom, fly-to)", catpaq::cmd_view},
};

void usage(FILE* out) {
    std::fprintf(out, "usage: catpaq <command> [options]\n\ncommands:\n");
    for (const Command& c : kCommands) std::fprintf(out, "  %-10s %s\n", c.name, c.summary);
    std::fprintf(out,
                 "\nRun 'catpaq help <command>' (or 'catpaq <command> --help') for the options of one command;\n"
                 "'catpaq --version' for the version. Exit status: 0 done, 1 failure, 2 usage error.\n");
}

void version() {
    std::printf("catpaq %s (dataset container version %u)\n", CATPAQ_VERSION, unsigned(catpaq::kArchiveVersion));
}

const Command* find_command(const std::string& name) {
    for (const Command& c : kCommands)
        if (name == c.name) return &c;
    return nullptr;
}

// An unknown command, with the closest known one if it looks like a typo. Exit status 2.
int unknown_command(const std::string& name) {
    std::vector<std::string> names;
    for (const Command& c : kCommands) names.push_back(c.name);
    std::string guess = catpaq::closest_match(name, names);
    if (guess.empty()) std::fprintf(stderr, "catpaq: unknown command '%s'\n\n", name.c_str());
    else std::fprintf(stderr, "catpaq: unknown command '%s'; did you mean '%s'?\n\n", name.c_str(), guess.c_str());
    usage(stderr);
    return 2;
}

int run_command(const Command& c, int argc, char** argv) {
    try {
        return c.run(argc, argv);
    } catch (const catpaq::UsageError& e) {
        std::fprintf(stderr, "catpaq %s: error: %s\n(see 'catpaq help %s')\n", c.name, e.what(), c.name);
        return 2;
    } catch (const catpaq::Error& e) {
        std::fprintf(stderr, "catpaq %s: error: %s\n", c.name, e.what());
        return 1;
    } catch (const std::bad_alloc&) {
        std::fprintf(stderr, "catpaq %s: error: out of memory\n", c.name);
        return 1;
    } catch (const std::exception& e) {
        // Nothing may end the program with an uncaught exception (status 134, no message).
        std::fprintf(stderr, "catpaq %s: error: %s\n", c.name, e.what());
        return 1;
    }
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        usage(stderr);
        return 2;
    }
    std::string first = argv[1];
    if (first == "--help" || first == "-h") {
        usage(stdout);
        return 0;
    }
    if (first == "--version" || first == "version") {
        version();
        return 0;
    }
    if (first == "help") {
        if (argc < 3) {
            usage(stdout);
            return 0;
        }
        const Command* c = find_command(argv[2]);
        if (!c) return unknown_command(argv[2]);
        char help[] = "--help";
        char* args[] = {argv[2], help, nullptr};
        return run_command(*c, 2, args);
    }
    if (const Command* c = find_command(first)) return run_command(*c, argc - 1, argv + 1);
    return unknown_command(first);
}
