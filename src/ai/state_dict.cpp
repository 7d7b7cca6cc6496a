#include "hanzo/fusion/ai/state_dict.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <memory>
#include <numeric>
#include <variant>

#include <fmt/format.h>

namespace hanzo::fusion::ai {
namespace {

// ---------------------------------------------------------------- zip archive (stored entries)

uint64_t little_endian(const std::string& bytes, std::size_t at, int size) {
  uint64_t value = 0;
  for (int i = size - 1; i >= 0; --i) value = (value << 8) | static_cast<uint8_t>(bytes[at + static_cast<std::size_t>(i)]);
  return value;
}

// Entry name -> (offset of the data, size) of every entry of the archive's central directory.
Result<std::map<std::string, std::pair<uint64_t, uint64_t>>> zip_entries(const std::string& bytes) {
  constexpr uint32_t kEndOfDirectory = 0x06054b50, kZip64Locator = 0x07064b50, kZip64End = 0x06064b50;
  constexpr uint32_t kDirectoryEntry = 0x02014b50, kLocalHeader = 0x04034b50;
  if (bytes.size() < 22) return Error("not a zip archive (too short)");
  std::size_t end = std::string::npos;
  for (std::size_t at = bytes.size() - 22;; --at) {  // the record ends with a comment of up to 64 KiB
    if (little_endian(bytes, at, 4) == kEndOfDirectory) {
      end = at;
      break;
    }
    if (at == 0 || bytes.size() - at > 22 + 65535) break;
  }
  if (end == std::string::npos) return Error("not a zip archive (no end-of-directory record): expected a torch.save file");
  uint64_t entries = little_endian(bytes, end + 10, 2), directory = little_endian(bytes, end + 16, 4);
  if ((entries == 0xFFFF || directory == 0xFFFFFFFF) && end >= 20 && little_endian(bytes, end - 20, 4) == kZip64Locator) {
    const uint64_t zip64_end = little_endian(bytes, end - 20 + 8, 8);
    if (zip64_end + 56 > bytes.size() || little_endian(bytes, zip64_end, 4) != kZip64End) return Error("corrupt zip64 end record");
    entries = little_endian(bytes, zip64_end + 32, 8);
    directory = little_endian(bytes, zip64_end + 48, 8);
  }
  std::map<std::string, std::pair<uint64_t, uint64_t>> found;
  uint64_t at = directory;
  for (uint64_t i = 0; i < entries; ++i) {
    if (at + 46 > bytes.size() || little_endian(bytes, at, 4) != kDirectoryEntry) return Error(fmt::format("corrupt zip directory (entry {})", i));
    const uint64_t method = little_endian(bytes, at + 10, 2);
    uint64_t size = little_endian(bytes, at + 24, 4), local = little_endian(bytes, at + 42, 4);
    const uint64_t name_length = little_endian(bytes, at + 28, 2), extra_length = little_endian(bytes, at + 30, 2);
    const uint64_t comment_length = little_endian(bytes, at + 32, 2);
    if (at + 46 + name_length + extra_length > bytes.size()) return Error("corrupt zip directory (a name beyond the file)");
    const std::string name = bytes.substr(at + 46, name_length);
    // Zip64 extra field: the 64-bit sizes / offset of the fields that hold 0xFFFFFFFF, in order.
    for (uint64_t extra = at + 46 + name_length; extra + 4 <= at + 46 + name_length + extra_length;) {
      const uint64_t id = little_endian(bytes, extra, 2), length = little_endian(bytes, extra + 2, 2);
      if (id == 0x0001) {
        uint64_t field = extra + 4;
        if (size == 0xFFFFFFFF) {
          size = little_endian(bytes, field, 8);
          field += 8;
        }
        if (little_endian(bytes, at + 20, 4) == 0xFFFFFFFF) field += 8;  // compressed size
        if (local == 0xFFFFFFFF) local = little_endian(bytes, field, 8);
      }
      extra += 4 + length;
    }
    if (method != 0) return Error(fmt::format("zip entry '{}' is compressed (method {}); torch.save stores entries", name, method));
    if (local + 30 > bytes.size() || little_endian(bytes, local, 4) != kLocalHeader) return Error(fmt::format("zip entry '{}': corrupt local header", name));
    const uint64_t data = local + 30 + little_endian(bytes, local + 26, 2) + little_endian(bytes, local + 28, 2);
    if (data + size > bytes.size()) return Error(fmt::format("zip entry '{}' ends beyond the file (truncated?)", name));
    found[name] = {data, size};
    at += 46 + name_length + extra_length + comment_length;
  }
  return found;
}

// ---------------------------------------------------------------- pickle machine

struct PickleValue;
using PickleList = std::shared_ptr<std::vector<PickleValue>>;  // tuples and lists
using PickleDict = std::shared_ptr<std::vector<std::pair<PickleValue, PickleValue>>>;
struct PickleGlobal {
  std::string module, name;
};
struct StorageReference {
  std::string type;  // "FloatStorage", ...
  std::string key;   // record data/<key>
};
struct Mark {};

struct PickleValue {
  std::variant<std::monostate, bool, int64_t, double, std::string, PickleList, PickleDict, PickleGlobal, StorageReference,
               std::shared_ptr<StateTensor>, Mark>
      value;
};

class Unpickler {
 public:
  Unpickler(const std::string& pickle, std::function<Result<StateTensor>(const StorageReference&, int64_t, const std::vector<int64_t>&,
                                                                        const std::vector<int64_t>&)> rebuild)
      : data_(pickle), rebuild_(std::move(rebuild)) {}

  Result<PickleValue> run() {
    while (true) {
      if (at_ >= data_.size()) return Error("the pickle ends without STOP");
      const auto opcode = static_cast<uint8_t>(data_[at_++]);
      if (opcode == '.') {
        if (stack_.empty()) return Error("the pickle's stack is empty at STOP");
        return stack_.back();
      }
      HANZO_RETURN_IF_ERROR(step(opcode));
    }
  }

 private:
  Result<uint64_t> read(int size) {
    if (at_ + static_cast<std::size_t>(size) > data_.size()) return Error("the pickle ends inside an instruction");
    const uint64_t value = little_endian(data_, at_, size);
    at_ += static_cast<std::size_t>(size);
    return value;
  }
  Result<std::string> read_bytes(uint64_t size) {
    if (at_ + size > data_.size()) return Error("the pickle ends inside a string");
    std::string text = data_.substr(at_, size);
    at_ += size;
    return text;
  }
  Result<std::string> read_line() {
    const std::size_t end = data_.find('\n', at_);
    if (end == std::string::npos) return Error("the pickle ends inside a GLOBAL");
    std::string line = data_.substr(at_, end - at_);
    at_ = end + 1;
    return line;
  }
  Result<PickleValue> pop() {
    if (stack_.empty()) return Error("pickle stack underflow");
    PickleValue value = std::move(stack_.back());
    stack_.pop_back();
    return value;
  }
  // The values above the topmost mark (which is removed).
  Result<std::vector<PickleValue>> pop_to_mark() {
    std::vector<PickleValue> items;
    while (!stack_.empty() && !std::holds_alternative<Mark>(stack_.back().value)) {
      items.push_back(std::move(stack_.back()));
      stack_.pop_back();
    }
    if (stack_.empty()) return Error("pickle MARK missing");
    stack_.pop_back();
    std::reverse(items.begin(), items.end());
    return items;
  }
  static PickleValue tuple(std::vector<PickleValue> items) { return {std::make_shared<std::vector<PickleValue>>(std::move(items))}; }

  Status set_items(const std::vector<PickleValue>& items) {
    if (stack_.empty() || !std::holds_alternative<PickleDict>(stack_.back().value)) return Error("SETITEMS on something other than a dict");
    if (items.size() % 2 != 0) return Error("SETITEMS with an odd number of values");
    auto& dict = *std::get<PickleDict>(stack_.back().value);
    for (std::size_t i = 0; i < items.size(); i += 2) dict.emplace_back(items[i], items[i + 1]);
    return ok_status();
  }

  Result<std::vector<int64_t>> integers(const PickleValue& value, const char* what) {
    const auto* list = std::get_if<PickleList>(&value.value);
    if (list == nullptr) return Error(fmt::format("tensor {}: expected a tuple", what));
    std::vector<int64_t> numbers;
    for (const PickleValue& item : **list) {
      const auto* number = std::get_if<int64_t>(&item.value);
      if (number == nullptr) return Error(fmt::format("tensor {}: expected integers", what));
      numbers.push_back(*number);
    }
    return numbers;
  }

  Result<PickleValue> call(const PickleGlobal& callable, const PickleList& arguments) {
    const std::string name = callable.module + "." + callable.name;
    const std::vector<PickleValue>& args = *arguments;
    if (name == "collections.OrderedDict") return PickleValue{std::make_shared<std::vector<std::pair<PickleValue, PickleValue>>>()};
    if (name == "torch._utils._rebuild_tensor_v2") {
      if (args.size() < 4) return Error("_rebuild_tensor_v2: too few arguments");
      const auto* storage = std::get_if<StorageReference>(&args[0].value);
      const auto* offset = std::get_if<int64_t>(&args[1].value);
      if (storage == nullptr || offset == nullptr) return Error("_rebuild_tensor_v2: expected a storage and an offset");
      std::vector<int64_t> shape, strides;
      HANZO_ASSIGN_OR_RETURN(shape, integers(args[2], "sizes"));
      HANZO_ASSIGN_OR_RETURN(strides, integers(args[3], "strides"));
      StateTensor tensor;
      HANZO_ASSIGN_OR_RETURN(tensor, rebuild_(*storage, *offset, shape, strides));
      return PickleValue{std::make_shared<StateTensor>(std::move(tensor))};
    }
    if (name == "torch._utils._rebuild_parameter") {
      if (args.empty() || !std::holds_alternative<std::shared_ptr<StateTensor>>(args[0].value)) return Error("_rebuild_parameter: expected a tensor");
      return args[0];
    }
    return Error(fmt::format("the pickle calls {}, which a state_dict does not use", name));
  }

  Status step(uint8_t opcode) {
    switch (opcode) {
      case 0x80: case 0x95: {  // PROTO, FRAME: nothing to keep
        auto skipped = read(opcode == 0x80 ? 1 : 8);
        return skipped ? ok_status() : Status(skipped.error());
      }
      case '(': stack_.push_back({Mark{}}); return ok_status();
      case ')': stack_.push_back(tuple({})); return ok_status();
      case ']': stack_.push_back(tuple({})); return ok_status();  // EMPTY_LIST
      case '}': stack_.push_back({std::make_shared<std::vector<std::pair<PickleValue, PickleValue>>>()}); return ok_status();
      case 'N': stack_.push_back({std::monostate{}}); return ok_status();
      case 0x88: stack_.push_back({true}); return ok_status();
      case 0x89: stack_.push_back({false}); return ok_status();
      case 'K': case 'M': case 'J': {  // BININT1, BININT2, BININT
        const int size = opcode == 'K' ? 1 : opcode == 'M' ? 2 : 4;
        uint64_t raw = 0;
        HANZO_ASSIGN_OR_RETURN(raw, read(size));
        const int64_t value = size == 4 ? static_cast<int64_t>(static_cast<int32_t>(raw)) : static_cast<int64_t>(raw);
        stack_.push_back({value});
        return ok_status();
      }
      case 0x8a: {  // LONG1: little-endian two's complement of n bytes
        uint64_t length = 0;
        HANZO_ASSIGN_OR_RETURN(length, read(1));
        if (length > 8) return Error("LONG1 beyond 64 bits");
        std::string digits;
        HANZO_ASSIGN_OR_RETURN(digits, read_bytes(length));
        int64_t value = 0;
        if (length > 0) {
          uint64_t raw = little_endian(digits, 0, static_cast<int>(length));
          if (length < 8 && (raw >> (8 * length - 1)) & 1U) raw |= ~uint64_t{0} << (8 * length);  // sign-extend
          value = static_cast<int64_t>(raw);
        }
        stack_.push_back({value});
        return ok_status();
      }
      case 'G': {  // BINFLOAT, big-endian
        std::string raw;
        HANZO_ASSIGN_OR_RETURN(raw, read_bytes(8));
        uint64_t bits = 0;
        for (char c : raw) bits = (bits << 8) | static_cast<uint8_t>(c);
        double value = 0.0;
        std::memcpy(&value, &bits, 8);
        stack_.push_back({value});
        return ok_status();
      }
      case 'X': case 0x8c: {  // BINUNICODE, SHORT_BINUNICODE
        uint64_t length = 0;
        HANZO_ASSIGN_OR_RETURN(length, read(opcode == 'X' ? 4 : 1));
        std::string text;
        HANZO_ASSIGN_OR_RETURN(text, read_bytes(length));
        stack_.push_back({std::move(text)});
        return ok_status();
      }
      case 'q': case 'r': case 0x94: {  // BINPUT, LONG_BINPUT, MEMOIZE
        if (stack_.empty()) return Error("memo of an empty stack");
        uint64_t index = memo_.size();
        if (opcode != 0x94) {
          HANZO_ASSIGN_OR_RETURN(index, read(opcode == 'q' ? 1 : 4));
        }
        memo_[index] = stack_.back();
        return ok_status();
      }
      case 'h': case 'j': {  // BINGET, LONG_BINGET
        uint64_t index = 0;
        HANZO_ASSIGN_OR_RETURN(index, read(opcode == 'h' ? 1 : 4));
        const auto found = memo_.find(index);
        if (found == memo_.end()) return Error(fmt::format("memo {} read before it was written", index));
        stack_.push_back(found->second);
        return ok_status();
      }
      case 'c': {  // GLOBAL module\nname\n
        PickleGlobal global;
        HANZO_ASSIGN_OR_RETURN(global.module, read_line());
        HANZO_ASSIGN_OR_RETURN(global.name, read_line());
        stack_.push_back({std::move(global)});
        return ok_status();
      }
      case 0x93: {  // STACK_GLOBAL
        PickleValue name, module;
        HANZO_ASSIGN_OR_RETURN(name, pop());
        HANZO_ASSIGN_OR_RETURN(module, pop());
        const auto* module_text = std::get_if<std::string>(&module.value);
        const auto* name_text = std::get_if<std::string>(&name.value);
        if (module_text == nullptr || name_text == nullptr) return Error("STACK_GLOBAL of non-strings");
        stack_.push_back({PickleGlobal{*module_text, *name_text}});
        return ok_status();
      }
      case 't': {
        std::vector<PickleValue> items;
        HANZO_ASSIGN_OR_RETURN(items, pop_to_mark());
        stack_.push_back(tuple(std::move(items)));
        return ok_status();
      }
      case 0x85: case 0x86: case 0x87: {  // TUPLE1..3
        std::vector<PickleValue> items(static_cast<std::size_t>(opcode - 0x84));
        for (auto item = items.rbegin(); item != items.rend(); ++item) HANZO_ASSIGN_OR_RETURN(*item, pop());
        stack_.push_back(tuple(std::move(items)));
        return ok_status();
      }
      case 'a': case 'e': {  // APPEND, APPENDS
        std::vector<PickleValue> items;
        if (opcode == 'a') {
          PickleValue item;
          HANZO_ASSIGN_OR_RETURN(item, pop());
          items.push_back(std::move(item));
        } else {
          HANZO_ASSIGN_OR_RETURN(items, pop_to_mark());
        }
        if (stack_.empty() || !std::holds_alternative<PickleList>(stack_.back().value)) return Error("APPEND to something other than a list");
        auto& list = *std::get<PickleList>(stack_.back().value);
        list.insert(list.end(), items.begin(), items.end());
        return ok_status();
      }
      case 's': {
        PickleValue value, key;
        HANZO_ASSIGN_OR_RETURN(value, pop());
        HANZO_ASSIGN_OR_RETURN(key, pop());
        return set_items({key, value});
      }
      case 'u': {
        std::vector<PickleValue> items;
        HANZO_ASSIGN_OR_RETURN(items, pop_to_mark());
        return set_items(items);
      }
      case 'Q': {  // BINPERSID: ('storage', StorageType, key, location, numel)
        PickleValue id;
        HANZO_ASSIGN_OR_RETURN(id, pop());
        const auto* fields = std::get_if<PickleList>(&id.value);
        if (fields == nullptr || (*fields)->size() < 3) return Error("persistent id: expected a storage tuple");
        const auto* type = std::get_if<PickleGlobal>(&(**fields)[1].value);
        const auto* key = std::get_if<std::string>(&(**fields)[2].value);
        if (type == nullptr || key == nullptr) return Error("persistent id: expected a storage type and key");
        stack_.push_back({StorageReference{type->name, *key}});
        return ok_status();
      }
      case 'R': {
        PickleValue arguments, callable;
        HANZO_ASSIGN_OR_RETURN(arguments, pop());
        HANZO_ASSIGN_OR_RETURN(callable, pop());
        const auto* global = std::get_if<PickleGlobal>(&callable.value);
        const auto* args = std::get_if<PickleList>(&arguments.value);
        if (global == nullptr || args == nullptr) return Error("REDUCE of something other than a global and a tuple");
        PickleValue result;
        HANZO_ASSIGN_OR_RETURN(result, call(*global, *args));
        stack_.push_back(std::move(result));
        return ok_status();
      }
      case 'b':  // BUILD: a state for the object below (an OrderedDict's _metadata): not needed
      {
        auto state = pop();
        return state ? ok_status() : Status(state.error());
      }
      default:
        return Error(fmt::format("pickle opcode 0x{:02x} at byte {} is not one a state_dict uses", opcode, at_ - 1));
    }
  }

  const std::string& data_;
  std::function<Result<StateTensor>(const StorageReference&, int64_t, const std::vector<int64_t>&, const std::vector<int64_t>&)> rebuild_;
  std::size_t at_ = 0;
  std::vector<PickleValue> stack_;
  std::map<uint64_t, PickleValue> memo_;
};

// One element of a storage as float.
Result<std::function<float(const char*)>> element_reader(const std::string& type, int& element_size) {
  if (type == "FloatStorage") {
    element_size = 4;
    return std::function<float(const char*)>([](const char* p) { float v; std::memcpy(&v, p, 4); return v; });
  }
  if (type == "DoubleStorage") {
    element_size = 8;
    return std::function<float(const char*)>([](const char* p) { double v; std::memcpy(&v, p, 8); return static_cast<float>(v); });
  }
  if (type == "LongStorage") {
    element_size = 8;
    return std::function<float(const char*)>([](const char* p) { int64_t v; std::memcpy(&v, p, 8); return static_cast<float>(v); });
  }
  if (type == "IntStorage") {
    element_size = 4;
    return std::function<float(const char*)>([](const char* p) { int32_t v; std::memcpy(&v, p, 4); return static_cast<float>(v); });
  }
  if (type == "HalfStorage") {
    element_size = 2;
    return std::function<float(const char*)>([](const char* p) {
      uint16_t h;
      std::memcpy(&h, p, 2);
      const uint32_t sign = (h & 0x8000U) << 16, exponent = (h >> 10) & 0x1FU, mantissa = h & 0x3FFU;
      float v;
      if (exponent == 0) {
        v = std::ldexp(static_cast<float>(mantissa), -24);
      } else if (exponent == 31) {
        v = mantissa == 0 ? INFINITY : NAN;
      } else {
        const uint32_t bits = ((exponent + 112) << 23) | (mantissa << 13);
        std::memcpy(&v, &bits, 4);
      }
      return sign ? -v : v;
    });
  }
  return Error(fmt::format("storage type {} is not supported (float, double, half, long, int)", type));
}

}  // namespace

int64_t StateTensor::numel() const { return std::accumulate(shape.begin(), shape.end(), int64_t{1}, std::multiplies<>()); }

Result<StateDict> read_state_dict(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error(fmt::format("{}: cannot open the model file", path));
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto context = [&](const Error& error) { return Error(fmt::format("{}: {}", path, error.message)); };
  auto entries = zip_entries(bytes);
  if (!entries) return context(entries.error());
  std::string prefix;
  bool found_pickle = false;
  for (const auto& [name, location] : *entries) {
    if (name == "data.pkl" || name.ends_with("/data.pkl")) {
      prefix = name.substr(0, name.size() - std::string("data.pkl").size());
      found_pickle = true;
      break;
    }
  }
  if (!found_pickle) return Error(fmt::format("{}: no data.pkl in the archive: not a torch.save file", path));
  const auto& [pickle_at, pickle_size] = entries->at(prefix + "data.pkl");
  const std::string pickle = bytes.substr(pickle_at, pickle_size);
  auto rebuild = [&](const StorageReference& storage, int64_t offset, const std::vector<int64_t>& shape,
                     const std::vector<int64_t>& strides) -> Result<StateTensor> {
    const auto record = entries->find(prefix + "data/" + storage.key);
    if (record == entries->end()) return Error(fmt::format("storage record data/{} is missing", storage.key));
    int element_size = 0;
    std::function<float(const char*)> element;
    HANZO_ASSIGN_OR_RETURN(element, element_reader(storage.type, element_size));
    if (shape.size() != strides.size()) return Error("a tensor's sizes and strides differ in length");
    const int64_t elements = static_cast<int64_t>(record->second.second) / element_size;
    StateTensor tensor;
    tensor.shape = shape;
    int64_t last = offset;  // the farthest element the view reaches
    for (std::size_t d = 0; d < shape.size(); ++d) {
      if (shape[d] < 0 || strides[d] < 0) return Error("negative tensor sizes or strides");
      if (shape[d] == 0) last = -1;
      if (last >= 0) last += (shape[d] - 1) * strides[d];
    }
    if (offset < 0 || last >= elements) return Error(fmt::format("a tensor reaches element {} of storage {} of {} elements", last, storage.key, elements));
    const int64_t count = tensor.numel();
    tensor.values.resize(static_cast<std::size_t>(count));
    const char* base = bytes.data() + record->second.first;
    std::vector<int64_t> index(shape.size(), 0);
    for (int64_t i = 0; i < count; ++i) {
      int64_t element_index = offset;
      for (std::size_t d = 0; d < shape.size(); ++d) element_index += index[d] * strides[d];
      tensor.values[static_cast<std::size_t>(i)] = element(base + element_index * element_size);
      for (int d = static_cast<int>(shape.size()) - 1; d >= 0; --d) {  // row-major increment
        if (++index[static_cast<std::size_t>(d)] < shape[static_cast<std::size_t>(d)]) break;
        index[static_cast<std::size_t>(d)] = 0;
      }
    }
    return tensor;
  };
  Unpickler unpickler(pickle, rebuild);
  auto root = unpickler.run();
  if (!root) return context(root.error());
  const auto* dict = std::get_if<PickleDict>(&root->value);
  if (dict == nullptr) return Error(fmt::format("{}: the pickle holds no dict: not a state_dict", path));
  StateDict state;
  for (const auto& [key, value] : **dict) {
    const auto* name = std::get_if<std::string>(&key.value);
    const auto* tensor = std::get_if<std::shared_ptr<StateTensor>>(&value.value);
    if (name == nullptr || tensor == nullptr) return Error(fmt::format("{}: a state_dict entry is not a named tensor", path));
    state[*name] = **tensor;
  }
  if (state.empty()) return Error(fmt::format("{}: the state_dict is empty", path));
  return state;
}

}  // namespace hanzo::fusion::ai
