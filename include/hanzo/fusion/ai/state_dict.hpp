#pragma once
// read_state_dict(): the tensors of a PyTorch state_dict saved with torch.save (the zip archive
// format of PyTorch >= 1.6: `<name>/data.pkl`, a pickle of an OrderedDict of tensors, and
// `<name>/data/<key>`, one file of raw little-endian values per storage), read without PyTorch.
//
// The pickle is interpreted by a small machine that knows only what state_dicts use (protocol
// 2-4 opcodes; the globals collections.OrderedDict, torch._utils._rebuild_tensor_v2 /
// _rebuild_parameter and torch.{Float,Double,Half,Long,Int}Storage); anything else is refused
// by name, so a pickle can never run code. Values are converted to float (float32 as stored;
// integer tensors such as BatchNorm's num_batches_tracked exactly while below 2^24).
//
// Failure: the file missing or unreadable, not a zip archive, compressed entries (torch.save
// stores them), a missing storage record, an opcode or global outside that set, a tensor whose
// sizes and strides reach beyond its storage. Errors name the file and what is wrong.

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::ai {

struct StateTensor {
  std::vector<int64_t> shape;  ///< sizes, outermost first (empty: a scalar)
  std::vector<float> values;   ///< contiguous, row-major (C order): shape's product values

  int64_t numel() const;
};

/// Parameter and buffer names ("block1.conv1.weight") to tensors.
using StateDict = std::map<std::string, StateTensor>;

Result<StateDict> read_state_dict(const std::string& path);

}  // namespace hanzo::fusion::ai
