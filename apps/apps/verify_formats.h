#pragma once
// `catpaq verify`, one front end per dataset format (apps/verify*.cpp): each runs its format's
// checks, prints the report and returns the exit status (0 when every check passes, else 1).
#include <cstddef>
#include <string>

namespace catpaq {

struct VerifyJob {
    std::string dataset;
    std::string original;  // the input it was converted from ("" when not given)
    size_t samples = 50000;  // surface samples per level and direction
    bool progress = false;
};

int verify_catp_dataset(const VerifyJob& job);
int verify_aqp_dataset(const VerifyJob& job);
int verify_points_dataset(const VerifyJob& job);

}  // namespace catpaq
