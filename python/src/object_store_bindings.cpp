// Python bindings of object_store::ObjectStore (object_store/object_store.hpp): files to and from
// a local folder or an S3-compatible store ("s3://bucket/prefix?endpoint=...", credentials from
// $AWS_ACCESS_KEY_ID / $AWS_SECRET_ACCESS_KEY), for hanzo.fusion.batch's s3:// inputs and
// outputs. Errors raise ValueError naming the object; a missing object's error names it too.

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "hanzo/fusion/object_store/object_store.hpp"

namespace py = pybind11;
using namespace hanzo::fusion;

namespace {

void raise_if_error(const Status& status) {
  if (!status) throw py::value_error(status.error().message);
}

class PyObjectStore {
 public:
  explicit PyObjectStore(const std::string& url) {
    Result<std::unique_ptr<object_store::ObjectStore>> opened = object_store::open_object_store(url);
    if (!opened) throw py::value_error(opened.error().message);
    store_ = std::move(opened).value();
  }
  std::string location() const { return store_->location(); }
  void put_file(const std::string& key, const std::string& path) {
    py::gil_scoped_release unlocked;
    raise_if_error(store_->put_file(key, path));
  }
  void get_to_file(const std::string& key, const std::string& path) const {
    py::gil_scoped_release unlocked;
    raise_if_error(store_->get_to_file(key, path));
  }
  std::vector<std::pair<std::string, uint64_t>> list(const std::string& prefix) const {
    Result<std::vector<object_store::ObjectInfo>> objects = store_->list(prefix);
    if (!objects) throw py::value_error(objects.error().message);
    std::vector<std::pair<std::string, uint64_t>> listed;
    for (const object_store::ObjectInfo& object : *objects) listed.emplace_back(object.key, object.size);
    return listed;
  }

 private:
  std::unique_ptr<object_store::ObjectStore> store_;
};

}  // namespace

void bind_object_store(py::module_& module) {
  py::class_<PyObjectStore>(module, "ObjectStore", "A local folder or an S3-compatible store holding whole files under keys; docs/python.md")
      .def(py::init<const std::string&>(), py::arg("url"), "A folder path, file:///path or s3://bucket/prefix[?endpoint=...&region=...]")
      .def("location", &PyObjectStore::location, "file:///abs/root or s3://bucket/prefix")
      .def("put_file", &PyObjectStore::put_file, py::arg("key"), py::arg("path"), "Stores the file at path under key (replacing it)")
      .def("get_to_file", &PyObjectStore::get_to_file, py::arg("key"), py::arg("path"), "Writes the object to path")
      .def("list", &PyObjectStore::list, py::arg("prefix") = "", "(key, size) of every object whose key starts with prefix, sorted");
}
