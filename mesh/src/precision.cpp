// Converter precisions (mesh/precision.h).
#include "mesh/precision.h"

#include <cmath>
#include <cstdlib>

namespace catpaq {

bool parse_precision(const std::string& text, Precision& out) {
    if (text.empty()) return false;
    const bool edges = text.back() == 'e' || text.back() == 'E';
    const std::string number = edges ? text.substr(0, text.size() - 1) : text;
    char* end = nullptr;
    const double v = std::strtod(number.c_str(), &end);
    if (number.empty() || end != number.c_str() + number.size() || !(v > 0) || !std::isfinite(v)) return false;
    out = edges ? Precision{0, v} : Precision{v, 0};
    return true;
}

}  // namespace catpaq
