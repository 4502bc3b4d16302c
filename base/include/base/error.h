#pragma once
// Errors that come from outside the program (bad files, bad options, network) are reported
// by throwing catpaq::Error with a message a user can act on; tools catch it in main,
// print it and exit non-zero. Caller bugs are assert()s instead.
#include <stdexcept>
#include <string>

namespace catpaq {

class Error : public std::runtime_error {
public:
    explicit Error(const std::string& message) : std::runtime_error(message) {}
};

// A command line a tool cannot act on: an unknown option, a malformed or out-of-range value, a
// missing or extra argument. Tools exit with status 2 for these and 1 when the work itself
// fails (a bad input file, a network error), so scripts can tell the two apart.
class UsageError : public Error {
public:
    using Error::Error;
};

// Throws Error(printf-style message).
[[noreturn]] void fail(const char* format, ...) __attribute__((format(printf, 1, 2)));
// Throws UsageError(printf-style message).
[[noreturn]] void usage_error(const char* format, ...) __attribute__((format(printf, 1, 2)));

// printf-style formatting into a std::string.
std::string strprintf(const char* format, ...) __attribute__((format(printf, 1, 2)));

}  // namespace catpaq
