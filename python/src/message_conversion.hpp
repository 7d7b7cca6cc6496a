#pragma once
// Conversion between the dataclasses of hanzo.fusion.messages (python/hanzo/fusion/messages.py)
// and msgs::SensorMessage / msgs::PoseEstimate. Fields are read by name, so any object with the
// dataclass's attributes converts. from_python raises TypeError for an object that is no sensor
// message and ValueError for a field of the wrong shape; values are checked by msgs::validate
// where the message is used.

#include <pybind11/pybind11.h>

#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::python {

msgs::SensorMessage sensor_message_from_python(pybind11::handle message);
pybind11::object to_python(const msgs::SensorMessage& message);
pybind11::object to_python(const msgs::PoseEstimate& pose);

}  // namespace hanzo::fusion::python
