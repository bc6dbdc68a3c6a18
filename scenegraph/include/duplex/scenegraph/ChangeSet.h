#pragma once
/// \file ChangeSet.h
/// What one SceneGraph::commit() changed, as observers receive it.

#include "duplex/scenegraph/NodeId.h"

#include <cstdint>
#include <ostream>
#include <vector>

namespace duplex {

/// Instance nodes only (groups and transform nodes never reach the tracer); each list sorted by id.
/// appeared and disappeared share no id with any other list. The lists describe the net effect of the whole batch, as
/// seen by a tracer:
/// - appeared: instances that are visible now and were not at the last commit (added, or shown, or
///   moved under a visible parent from a hidden one);
/// - disappeared: instances visible at the last commit that are not now (removed or hidden);
/// - moved: visible before and after, world transform changed (its own, an ancestor's, re-parented);
/// - object_changed: visible before and after, given another object or its object was replaced
///   in the library (SceneGraph::replaceObject, deformObject; may also have moved);
/// - mask_changed: visible before and after, mask changed (may also have moved or changed object).
/// An instance that moved and was given another object is listed in both moved and object_changed.
/// An instance added and removed within one batch appears nowhere.
struct ChangeSet {
  std::uint64_t commit = 0;            ///< 1 for the first commit, +1 per commit that changed anything
  std::vector<NodeId> appeared;        ///< instances visible now and not at the last commit
  std::vector<NodeId> disappeared;     ///< instances visible at the last commit and not now
  std::vector<NodeId> moved;           ///< visible before and after, world transform changed
  std::vector<NodeId> object_changed;  ///< visible before and after, object replaced
  std::vector<NodeId> mask_changed;    ///< visible before and after, mask changed
  /// Library objects replaced by this commit (new geometry: deformed, re-meshed), sorted; their
  /// visible instances are in object_changed.
  std::vector<ObjectId> objects_changed;

  /// Whether nothing changed (commit still carries the number of the last commit that did).
  [[nodiscard]] bool empty() const {
    return appeared.empty() && disappeared.empty() && moved.empty() && object_changed.empty() && mask_changed.empty() &&
           objects_changed.empty();
  }
};

/// Writes the commit number and the non-empty lists, for logs and test messages.
std::ostream& operator<<(std::ostream& os, const ChangeSet& c);

}  // namespace duplex
