#pragma once
/// \file TopLevelMemory.h
/// What the top level holds per instance, for checks against the memory limit (MemoryLimit.h)
/// before a scene of many instances is built.

#include <cstdint>

namespace duplex {

/// Bytes the top level needs per instance: its description while the tree is built (InstanceDesc),
/// its slot's record, filter, owner and world box, its edit while pending, its entries in the
/// slot and pending maps, its tree references (twice, for boxes that straddle splits) and the
/// builder's working references (two lists of them).
[[nodiscard]] std::uint64_t topLevelBytesPerInstance();

}  // namespace duplex
