#pragma once
/// \file NodeId.h
/// Stable identifiers of scene-graph nodes and library objects.

#include <cstdint>

namespace duplex {

/// A scene-graph node's id: assigned at creation, never reused within one SceneGraph, stable across
/// edits (re-parenting keeps it). The root is kRootNode.
using NodeId = std::uint32_t;
inline constexpr NodeId kRootNode = 0;
inline constexpr NodeId kInvalidNode = 0xFFFFFFFFu;

/// A handle of an object in an ObjectLibrary (its position; objects are never removed).
using ObjectId = std::uint32_t;
inline constexpr ObjectId kInvalidObject = 0xFFFFFFFFu;

}  // namespace duplex
