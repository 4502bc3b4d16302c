#include "log.h"

#include <chrono>
#include <cstdarg>
#include <cstdio>
#include <ctime>

#include "base/error.h"

namespace catpaq {

const char* log_level_name(LogLevel level) {
    switch (level) {
        case LogLevel::Error: return "error";
        case LogLevel::Warn: return "warn";
        case LogLevel::Info: return "info";
        case LogLevel::Debug: return "debug";
    }
    return "unknown";
}

LogLevel parse_log_level(const std::string& text) {
    for (LogLevel level : {LogLevel::Error, LogLevel::Warn, LogLevel::Info, LogLevel::Debug})
        if (text == log_level_name(level)) return level;
    fail("unknown log level '%s' (expected error, warn, info or debug)", text.c_str());
}

namespace serve {

static void stderr_sink(LogLevel level, std::string_view message) {
    auto now = std::chrono::system_clock::now();
    auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count();
    time_t seconds = time_t(ms / 1000);
    struct tm tm{};
    gmtime_r(&seconds, &tm);
    char prefix[64];
    int n = std::snprintf(prefix, sizeof prefix, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ %-5s ", tm.tm_year + 1900,
                          tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, int(ms % 1000),
                          log_level_name(level));
    std::string line(prefix, size_t(n));
    line.append(message);
    line.push_back('\n');
    std::fwrite(line.data(), 1, line.size(), stderr);
}

Logger::Logger(LogLevel level, std::function<void(LogLevel, std::string_view)> sink)
    : level_(level), sink_(sink ? std::move(sink) : stderr_sink) {}

void Logger::log(LogLevel level, std::string_view message) const {
    if (enabled(level)) sink_(level, message);
}

void Logger::logf(LogLevel level, const char* format, ...) const {
    if (!enabled(level)) return;
    char buffer[1024];
    va_list args;
    va_start(args, format);
    int n = std::vsnprintf(buffer, sizeof buffer, format, args);
    va_end(args);
    if (n < 0) return;
    sink_(level, std::string_view(buffer, size_t(n) < sizeof buffer ? size_t(n) : sizeof buffer - 1));
}

}  // namespace serve
}  // namespace catpaq
