#pragma once
// Conforming cuts of the diamond hierarchy, for tests, `verify` and exports (the client's cut
// engine keeps its own incremental front; this is the plain set form).
//
// A cut is a set R of refined diamonds closed under parents. The tetrahedra on screen are, for
// every diamond D not in R, the slots whose creating parent (slot_parent) is in R — or all slots
// of the root while it is unrefined. Diamonds absent from the index hold no geometry; they can be
// in R (they draw nothing) and must be, when a present child needs them refined.
#include <cstdint>
#include <unordered_set>
#include <utility>
#include <vector>

#include "catp/dataset.h"

namespace catpaq {

class RefinedSet {
public:
    bool contains(DiamondId id) const { return refined_.count(id.bits) != 0; }
    // Refines `id` and, first, every ancestor it needs (closure under parents).
    void refine(DiamondId id);
    size_t size() const { return refined_.size(); }
    const std::unordered_set<uint64_t>& ids() const { return refined_; }

private:
    std::unordered_set<uint64_t> refined_;
};

struct DrawnSlot {
    const ArchiveEntry* entry;
    int slot;
};

// The fragments drawn for cut R.
std::vector<DrawnSlot> drawn_slots(const CatpIndex& index, const RefinedSet& refined);

}  // namespace catpaq
