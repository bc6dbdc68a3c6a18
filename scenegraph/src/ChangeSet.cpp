/// \file ChangeSet.cpp
/// Readable printing for test failures and logs.

#include "duplex/scenegraph/ChangeSet.h"

namespace duplex {

namespace {
void printList(std::ostream& os, const char* label, const std::vector<NodeId>& ids) {
  os << ", " << label << "=[";
  for (std::size_t i = 0; i < ids.size(); ++i) os << (i ? "," : "") << ids[i];
  os << ']';
}
}  // namespace

std::ostream& operator<<(std::ostream& os, const ChangeSet& c) {
  os << "ChangeSet{commit=" << c.commit;
  printList(os, "appeared", c.appeared);
  printList(os, "disappeared", c.disappeared);
  printList(os, "moved", c.moved);
  printList(os, "object_changed", c.object_changed);
  printList(os, "mask_changed", c.mask_changed);
  if (!c.objects_changed.empty()) printList(os, "objects_changed", c.objects_changed);
  return os << '}';
}

}  // namespace duplex
