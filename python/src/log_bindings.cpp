// Python bindings of the sensor log (io/sensor_log.hpp): LogReader yields (topic, log_time_ns,
// message) with the messages as hanzo.fusion.messages dataclasses; LogWriter writes them.
// hanzo/fusion/log.py wraps both (read_log, LogWriter as a context manager). A message that
// does not decode or validate raises ValueError naming topic and time; nothing is written then.

#include <memory>
#include <optional>
#include <string>

#include <fmt/format.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "hanzo/fusion/io/sensor_log.hpp"
#include "message_conversion.hpp"

namespace py = pybind11;
using namespace hanzo::fusion;

namespace {

class PyLogReader {
 public:
  explicit PyLogReader(const std::string& path) {
    Result<std::unique_ptr<io::SensorLogReader>> reader = io::SensorLogReader::open(path);
    if (!reader) throw py::value_error(reader.error().message);
    reader_ = std::move(*reader);
  }

  // (topic, log_time_ns, message) or None at the end.
  std::optional<py::tuple> next() {
    io::LogEntry entry;
    const Result<bool> read = reader_->next(entry);
    if (!read) throw py::value_error(read.error().message);
    if (!*read) return std::nullopt;
    py::object message = std::visit([](const auto& m) { return python::to_python(m); }, entry.message);
    return py::make_tuple(entry.topic, entry.log_time.nanoseconds(), message);
  }

  uint64_t skipped() const { return reader_->skipped_messages(); }

 private:
  std::unique_ptr<io::SensorLogReader> reader_;
};

class PyLogWriter {
 public:
  PyLogWriter(const std::string& path, const std::string& compression, const std::string& image_compression, bool foxglove_channels) {
    io::SensorLogWriterConfig config;
    const Result<io::mcap::Compression> chunks = io::mcap::compression_from_name(compression);
    if (!chunks) throw py::value_error(fmt::format("compression: {}", chunks.error().message));
    config.mcap.compression = *chunks;
    const std::optional<io::ImageCompression> images = io::image_compression_from_string(image_compression);
    if (!images) throw py::value_error(fmt::format("image_compression: expected none, png or jpeg, got '{}'", image_compression));
    config.image_compression = *images;
    config.foxglove_channels = foxglove_channels;
    Result<std::unique_ptr<io::SensorLogWriter>> writer = io::SensorLogWriter::open(path, config);
    if (!writer) throw py::value_error(writer.error().message);
    writer_ = std::move(*writer);
  }

  void write(const std::string& topic, const py::object& message, const std::string& sensor_name) {
    if (!writer_) throw py::value_error("LogWriter: the log is closed");
    const msgs::SensorMessage converted = python::sensor_message_from_python(message);
    const Status written = writer_->write(topic, converted, sensor_name);
    if (!written) throw py::value_error(written.error().message);
  }

  void close() {
    if (!writer_) return;
    const Status closed = writer_->close();
    writer_.reset();
    if (!closed) throw py::value_error(closed.error().message);
  }

 private:
  std::unique_ptr<io::SensorLogWriter> writer_;
};

}  // namespace

void bind_sensor_log(py::module_& module) {
  py::class_<PyLogReader>(module, "LogReader", "Reads a sensor log (MCAP) in log-time order; use hanzo.fusion.read_log")
      .def(py::init<const std::string&>(), py::arg("path"))
      .def("next", &PyLogReader::next, "(topic, log_time_ns, message) or None at the end; ValueError for a message that does not decode")
      .def_property_readonly("skipped", &PyLogReader::skipped, "Messages of channels that carry no hanzo.fusion.v1 schema");
  py::class_<PyLogWriter>(module, "LogWriter", "Writes a sensor log (MCAP) that run, replay and the server read")
      .def(py::init<const std::string&, const std::string&, const std::string&, bool>(), py::arg("path"), py::arg("compression") = "zstd",
           py::arg("image_compression") = "none", py::arg("foxglove_channels") = true,
           "compression: zstd, lz4 or none (chunks); image_compression: none, png or jpeg")
      .def("write", &PyLogWriter::write, py::arg("topic"), py::arg("message"), py::arg("sensor_name") = "",
           "Validates and appends a hanzo.fusion.messages message on topic at its timestamp")
      .def("close", &PyLogWriter::close, "Finishes the file (summary and footer)");
}
