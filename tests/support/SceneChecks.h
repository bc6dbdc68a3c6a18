#pragma once
/// \file SceneChecks.h
/// References over a SceneGraph: its visible instances as the brute force of TwoLevelChecks.h
/// takes them.

#include "TwoLevelChecks.h"

#include "duplex/scenegraph/SceneGraph.h"

namespace duplex::test {

/// The visible instances as the graph says after its last commit (world transforms, masks).
inline Model visibleModel(const SceneGraph& graph) {
  Model m;
  for (const NodeId id : graph.visibleInstances()) {
    const NodeInfo info = graph.node(id);
    m[id] = InstanceDesc{graph.library().get(info.object), graph.worldTransform(id), id, info.mask};
  }
  return m;
}

}  // namespace duplex::test
