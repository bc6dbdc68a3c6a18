#pragma once
/// \file SceneMemory.h
/// What a scene holds per instance node, for checks against the memory limit (MemoryLimit.h)
/// before a scene file's instances are added.

#include <cstdint>

namespace duplex {

/// Bytes one instance node needs in a graph traced by a SceneTracer: the graph's node record, its
/// slots, its name-index entry, its undo and touched records and its change-set entry until the
/// commit, and the top level's share (topLevelBytesPerInstance()). A name longer than the short
/// string buffer adds its length.
[[nodiscard]] std::uint64_t sceneBytesPerInstance();

}  // namespace duplex
