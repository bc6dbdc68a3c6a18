#pragma once
// Private to accel/util/src (and its test): the control-group part of the default memory limit.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace duplex::detail {

// The smallest memory limit of the control group that `proc_self_cgroup` (the text of
// /proc/self/cgroup) names and of the groups above it, read under `cgroup_root` (/sys/fs/cgroup):
// cgroup v2 "0::<path>" lines read <root><path>/memory.max, v1 lines whose controllers include
// "memory" read <root>/memory<path>/memory.limit_in_bytes. "max", values of 2^62 and more (v1's
// "no limit") and missing files are no limit; nullopt when nothing limits.
std::optional<std::uint64_t> cgroupMemoryLimit(std::string_view proc_self_cgroup, const std::string& cgroup_root);

}  // namespace duplex::detail
