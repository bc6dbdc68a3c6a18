#pragma once
/// \file NodeId.h
/// Stable identifiers of scene-graph nodes and library objects.

#include <cstdint>

namespace duplex {

/// A scene-graph node's id: assigned at creation, never reused within one SceneGraph, stable across
/// edits (re-parenting keeps it). The root is kRootNode.
using NodeId = std::uint32_t;
inline constexpr NodeId kRootNode = 0;               ///< the root group's id (the graph has one from creation)
inline constexpr NodeId kInvalidNode = 0xFFFFFFFFu;  ///< no node (the root's parent, a miss's instance)

/// A handle of an object in an ObjectLibrary (its position; objects are never removed).
using ObjectId = std::uint32_t;
inline constexpr ObjectId kInvalidObject = 0xFFFFFFFFu;  ///< no object (the object of a group or transform node)

}  // namespace duplex
