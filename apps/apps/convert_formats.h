#pragma once
// `catpaq convert`, one converter front end per output format (apps/convert*.cpp). Each reads
// its own options from `options` (the shared ones, -o and --quiet, are read by cmd_convert),
// calls its module's converter and prints the report: a table for a person, or with --json one
// JSON object on stdout for scripts.
#include <string>

#include "base/options.h"

namespace catpaq {

struct ConvertJob {
    std::string input, output;
    bool quiet = false;  // no progress and no table (warnings still go to stderr)
    bool json = false;   // the report as one JSON object on stdout
};

// Removes temporaries an interrupted run left next to the output (after the options are read).
void prepare_output(const ConvertJob& job);

// Warns on stderr when the dataset written to job.output needs more than the 64 KiB of a first
// request before a client draws it (the prefix lists every node): `fewer_nodes` names the option
// that makes nodes larger, hence fewer.
void warn_about_first_frame(const ConvertJob& job, const char* fewer_nodes);

int convert_catp(Options& options, const ConvertJob& job);
int convert_aqp(Options& options, const ConvertJob& job);
int convert_points(Options& options, const ConvertJob& job);

}  // namespace catpaq
