#include "base/output_path.h"

#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <dirent.h>
#include <sys/stat.h>
#include <unistd.h>

#include "base/error.h"

namespace catpaq {

std::string directory_of(const std::string& path) {
    size_t slash = path.find_last_of('/');
    return slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
}

namespace {

void check_writable_directory(const std::string& dir, const std::string& path, const std::string& what) {
    struct stat st{};
    if (::stat(dir.c_str(), &st) != 0)
        fail("%s '%s': the directory '%s' does not exist", what.c_str(), path.c_str(), dir.c_str());
    if (!S_ISDIR(st.st_mode)) fail("%s '%s': '%s' is not a directory", what.c_str(), path.c_str(), dir.c_str());
    if (::access(dir.c_str(), W_OK | X_OK) != 0)
        fail("%s '%s': cannot write in '%s': %s", what.c_str(), path.c_str(), dir.c_str(), std::strerror(errno));
}

}  // namespace

void check_output_file(const std::string& path, const std::string& what) {
    if (path.empty() || path.back() == '/') fail("%s '%s': expected a file name", what.c_str(), path.c_str());
    struct stat st{};
    if (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode))
        fail("%s '%s' is a directory; give a file name (e.g. '%s/NAME')", what.c_str(), path.c_str(), path.c_str());
    check_writable_directory(directory_of(path), path, what);
}

void prepare_output_directory(const std::string& path, const std::string& what) {
    if (path.empty()) fail("%s: expected a directory", what.c_str());
    struct stat st{};
    if (::stat(path.c_str(), &st) == 0) {
        if (!S_ISDIR(st.st_mode)) fail("%s '%s' exists and is not a directory", what.c_str(), path.c_str());
    } else {
        // Parents first, as mkdir -p.
        for (size_t at = 1; at <= path.size(); ++at) {
            if (at != path.size() && path[at] != '/') continue;
            std::string prefix = path.substr(0, at);
            if (::mkdir(prefix.c_str(), 0777) != 0 && errno != EEXIST)
                fail("%s '%s': cannot create '%s': %s", what.c_str(), path.c_str(), prefix.c_str(), std::strerror(errno));
        }
        if (::stat(path.c_str(), &st) != 0 || !S_ISDIR(st.st_mode))
            fail("%s '%s': cannot create the directory", what.c_str(), path.c_str());
    }
    check_writable_directory(path, path, what);
}

std::vector<std::string> remove_stale_temporaries(const std::string& output) {
    std::vector<std::string> removed;
    std::string dir = directory_of(output);
    std::string name = output.substr(output.find_last_of('/') == std::string::npos ? 0 : output.find_last_of('/') + 1);
    DIR* d = ::opendir(dir.c_str());
    if (!d) return removed;
    while (dirent* e = ::readdir(d)) {
        std::string entry = e->d_name;
        for (const char* suffix : {".tmp.", ".nodes.tmp."}) {
            std::string prefix = name + suffix;
            if (entry.size() <= prefix.size() || entry.compare(0, prefix.size(), prefix) != 0) continue;
            std::string digits = entry.substr(prefix.size());
            if (digits.find_first_not_of("0123456789") != std::string::npos || digits.size() > 9) continue;
            pid_t pid = pid_t(std::atol(digits.c_str()));
            if (pid <= 0 || pid == ::getpid()) continue;
            if (::kill(pid, 0) == 0 || errno != ESRCH) continue;  // that process still runs
            std::string full = dir + "/" + entry;
            if (::unlink(full.c_str()) == 0) removed.push_back(full);
        }
    }
    ::closedir(d);
    return removed;
}

}  // namespace catpaq
