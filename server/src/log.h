#pragma once
// Log lines for the server: a level filter in front of the settings' sink (stderr by default,
// "2024-05-01T12:00:00.123Z info message", one write per line so threads do not interleave).
#include <functional>
#include <string>
#include <string_view>

#include "server/server.h"

namespace catpaq::serve {

class Logger {
public:
    Logger(LogLevel level, std::function<void(LogLevel, std::string_view)> sink);

    bool enabled(LogLevel level) const { return int(level) <= int(level_); }
    void log(LogLevel level, std::string_view message) const;
    void logf(LogLevel level, const char* format, ...) const __attribute__((format(printf, 3, 4)));

private:
    LogLevel level_;
    std::function<void(LogLevel, std::string_view)> sink_;
};

}  // namespace catpaq::serve
