#include "catp/cut.h"

namespace catpaq {

void RefinedSet::refine(DiamondId id) {
    if (contains(id)) return;
    // Parents first (iteratively deep-first), so the set stays closed at every step.
    std::vector<DiamondId> stack{id};
    while (!stack.empty()) {
        DiamondId d = stack.back();
        if (contains(d)) {
            stack.pop_back();
            continue;
        }
        bool ready = true;
        for (DiamondId p : diamond_parents(d))
            if (!contains(p)) {
                stack.push_back(p);
                ready = false;
            }
        if (ready) {
            refined_.insert(d.bits);
            stack.pop_back();
        }
    }
}

std::vector<DrawnSlot> drawn_slots(const CatpIndex& index, const RefinedSet& refined) {
    std::vector<DrawnSlot> out;
    DiamondId root = root_diamond();
    for (const ArchiveEntry& e : index.entries()) {
        DiamondId id{e.key};
        if (refined.contains(id)) continue;
        uint8_t mask = uint8_t(e.flags & 0xff);
        if (!mask) continue;
        DiamondInfo info;
        bool have_info = false;
        for (int s = 0; s < 8; ++s) {
            if (!(mask & (1 << s))) continue;
            bool present = id == root;
            if (!present) {
                if (!have_info) {
                    info = diamond_info(id);
                    have_info = true;
                }
                present = refined.contains(slot_parent(info, s));
            }
            if (present) out.push_back({&e, s});
        }
    }
    return out;
}

}  // namespace catpaq
