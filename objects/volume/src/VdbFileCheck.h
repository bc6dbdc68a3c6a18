#pragma once
// Private to objects/volume/src: a structural check of a .vdb file before OpenVDB reads it.

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace duplex {

/// One grid as the file's descriptor table lists it.
struct VdbGridExtent {
  std::string unique_name;
  std::string type;
  std::string instance_parent;
  std::int64_t grid_pos = 0, block_pos = 0, end_pos = 0;  ///< byte offsets in the file
};

/// Walks the header, file metadata and grid descriptor table of a .vdb file (OpenVDB file format
/// 222 to 224, the versions OpenVDB 10 reads fully) without OpenVDB, and checks every length and
/// offset against the file size: each grid must start right after its descriptor, its data block
/// must lie inside it, and it must end inside the file (the next descriptor starts there).
/// Metadata (the file's and every grid's) must be what OpenVDB's readers consume: fixed-size types
/// declare their size, delayed-load metadata counts no more leaves than the grid's bytes can hold
/// and its blosc headers give the arrays' sizes; every grid's transform (frustum maps included) is
/// walked, since OpenVDB reads all grids' headers when it lists them.
/// Then walks the tree of every float grid (not instances): topology, tile values and leaf buffers,
/// and checks that each compressed chunk declares exactly the bytes its values need (blosc: also
/// its header's sizes), that the topology ends at the grid's block position and the buffers at its
/// end. OpenVDB 10 trusts those lengths: from a stream cut short it allocates whatever a short read
/// left in them, and a damaged raw-chunk length makes it write past its buffer; this check lets
/// such files fail first. Half floats: exactly when the grid's is_saved_as_half_float entry says so.
/// Returns the grids; throws FileError naming `file`, the grid and the first inconsistency.
std::vector<VdbGridExtent> checkVdbFileStructure(const std::filesystem::path& file);

}  // namespace duplex
