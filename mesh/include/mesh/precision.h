#pragma once
// A converter's precision: the finest level's largest distance from the input it guarantees,
// given in model units or in mean input edges (`convert --precision`, CATP and AQP alike).
#include <string>

namespace catpaq {

// `model_units` if positive, else `mean_edges` times the input's mean edge length.
struct Precision {
    double model_units = 0;
    double mean_edges = 0.1;
};
// Parses "0.001" (model units) or "0.1e" (a fraction of the mean input edge); false if invalid.
bool parse_precision(const std::string& text, Precision& out);

}  // namespace catpaq
