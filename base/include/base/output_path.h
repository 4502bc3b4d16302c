#pragma once
// Output paths checked before any work is done, so that a command refuses a path it cannot
// write at once (and names it), instead of failing at the end of a long run. Also the clean-up
// of temporary files that a killed run may have left next to an output.
#include <string>
#include <vector>

namespace catpaq {

// The directory part of `path`: "." when it has none, "/" for a file at the root.
std::string directory_of(const std::string& path);

// Checks that `path` can be written as a file: it is not a directory, and its directory exists
// and is writable. Throws Error naming `what` (the option, e.g. "-o") and the path.
void check_output_file(const std::string& path, const std::string& what);

// Creates the directory `path` (and its parents) if needed, and checks it is a writable
// directory. Throws Error naming `what` and the path (e.g. when `path` is an existing file).
void prepare_output_directory(const std::string& path, const std::string& what);

// Removes the temporaries older versions and interrupted runs named `OUTPUT.tmp.PID` and
// `OUTPUT.nodes.tmp.PID` next to `output`, when process PID no longer runs (a run killed by
// SIGKILL cannot clean up after itself). Returns the paths removed.
std::vector<std::string> remove_stale_temporaries(const std::string& output);

}  // namespace catpaq
