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

// Throws Error(printf-style message).
[[noreturn]] void fail(const char* format, ...) __attribute__((format(printf, 1, 2)));

// printf-style formatting into a std::string.
std::string strprintf(const char* format, ...) __attribute__((format(printf, 1, 2)));

}  // namespace catpaq
