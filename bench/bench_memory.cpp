// Memory of long sessions (issue: "resident size after 10 minutes within 10 % of that after 2
// minutes"): the simulated drone's figure eights (examples/scenarios/drone.yaml, stereo cameras +
// IMU, its trajectory made `--seconds` long) and the urban car's loop (urban_vehicle.yaml: IMU,
// LiDAR, GNSS, wheels, camera, radar) driven as many laps as fill `--seconds`, streamed straight
// from the simulator into a Session as the server runs one (the generated configuration, loop
// closure on, no trajectory kept), resident memory sampled every 60 s of log. Each configuration
// runs in a fresh process; the drone also with every keyframe's variables kept
// (visual_inertial_window_keyframes 0, the graph before the window).
//
//   build/bench/bench_memory [--seconds 600] [--scenario drone|urban_vehicle] [--json] [--window-only]
//
// --window-only runs the default configuration alone in this process (for heap profilers:
// heaptrack build/bench/bench_memory --seconds 300 --scenario drone --window-only).
//
// Reports per configuration: resident MB at each minute, growth from 2 min to the end, real-time
// factor (simulation included: it renders the images), landmarks, loop closures and LiDAR map
// keyframes kept (and offered at places the map had: revisits).
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"

namespace hf = hanzo::fusion;

namespace {

double resident_megabytes() {
  long pages_total = 0, pages_resident = 0;
  if (std::FILE* statm = std::fopen("/proc/self/statm", "r")) {
    if (std::fscanf(statm, "%ld %ld", &pages_total, &pages_resident) != 2) pages_resident = 0;
    std::fclose(statm);
  }
  return static_cast<double>(pages_resident) * static_cast<double>(::sysconf(_SC_PAGESIZE)) / 1e6;
}

struct Outcome {
  std::vector<double> resident_mb;  // at 60, 120, ... s of log
  double seconds = 0.0;             // wall time
  uint64_t landmarks = 0;
  uint64_t loop_closures = 0;
  uint64_t map_keyframes = 0;  // LiDAR map keyframes kept
  uint64_t map_revisits = 0;   // offered at places the map had, not kept
};

// The drone's figure eights made `seconds` long, or the urban car's loop driven as many laps as
// fill them.
hf::sim::Scenario long_scenario(const std::string& name, double seconds) {
  hf::sim::Scenario scenario = hf::sim::load_scenario(std::string(HANZO_SOURCE_DIR) + "/examples/scenarios/" + name + ".yaml").value();
  scenario.num_threads = 0;
  if (name == "drone") {
    scenario.drone.duration = seconds;
  } else {
    const double lap = (hf::sim::ScenarioSimulation::create(scenario).value()->end_time() - scenario.start_time).seconds();
    scenario.ground_path.laps = std::max(1, static_cast<int>(std::ceil(seconds / lap)));
  }
  return scenario;
}

Outcome run(const std::string& name, double seconds, int window) {
  const hf::sim::Scenario scenario = long_scenario(name, seconds);
  auto simulation = hf::sim::ScenarioSimulation::create(scenario).value();
  simulation->set_record_imu_bias_truth(false);  // the session's memory, not the simulator's records
  hf::pipeline::SessionConfig config = hf::pipeline::SessionConfig::from(hf::sim::scenario_fusion_config(scenario));
  config.keep_trajectory = false;
  config.visual_inertial_window_keyframes = window;
  auto session = hf::pipeline::Session::create(hf::sim::scenario_fusion_config(scenario), hf::sim::scenario_calibration(scenario), config).value();
  Outcome outcome;
  const hf::Timestamp start = simulation->trajectory().start_time();
  const auto began = std::chrono::steady_clock::now();
  const hf::Status status = simulation->run([&](const hf::sim::ScenarioSensor& sensor, hf::msgs::SensorMessage&& message) -> hf::Status {
    const double at = (hf::msgs::timestamp_of(message) - start).seconds();
    while (at >= 60.0 * static_cast<double>(outcome.resident_mb.size() + 1)) outcome.resident_mb.push_back(resident_megabytes());
    (void)session->push(sensor.name, std::move(message));
    return hf::ok_status();
  });
  if (!status) std::fprintf(stderr, "bench_memory: %s\n", status.error().message.c_str());
  session->flush();
  outcome.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - began).count();
  outcome.landmarks = session->mapping_summary().graph_landmarks;
  outcome.loop_closures = session->mapping_summary().loop_closures;
  outcome.map_keyframes = session->mapping_summary().map_keyframes;
  outcome.map_revisits = session->mapping_summary().map_revisits;
  return outcome;
}

// run() in a child process (each configuration from a fresh heap), its outcome through a pipe.
Outcome run_in_child(const std::string& name, double seconds, int window) {
  int pipe_ends[2];
  if (::pipe(pipe_ends) != 0) return {};
  const pid_t child = ::fork();
  if (child == 0) {
    ::close(pipe_ends[0]);
    const Outcome outcome = run(name, seconds, window);
    const std::string text = nlohmann::json{{"resident_mb", outcome.resident_mb}, {"seconds", outcome.seconds}, {"landmarks", outcome.landmarks},
                                            {"loop_closures", outcome.loop_closures}, {"map_keyframes", outcome.map_keyframes},
                                            {"map_revisits", outcome.map_revisits}}.dump();
    if (::write(pipe_ends[1], text.data(), text.size()) < 0) std::_Exit(2);
    std::_Exit(0);
  }
  ::close(pipe_ends[1]);
  std::string text;
  char buffer[4096];
  for (ssize_t got; (got = ::read(pipe_ends[0], buffer, sizeof(buffer))) > 0;) text.append(buffer, static_cast<std::size_t>(got));
  ::close(pipe_ends[0]);
  int child_status = 0;
  ::waitpid(child, &child_status, 0);
  Outcome outcome;
  if (text.empty()) return outcome;
  const nlohmann::json parsed = nlohmann::json::parse(text);
  outcome.resident_mb = parsed["resident_mb"].get<std::vector<double>>();
  outcome.seconds = parsed["seconds"];
  outcome.landmarks = parsed["landmarks"];
  outcome.loop_closures = parsed["loop_closures"];
  outcome.map_keyframes = parsed["map_keyframes"];
  outcome.map_revisits = parsed["map_revisits"];
  return outcome;
}

}  // namespace

int main(int argc, char** argv) {
  double seconds = 600.0;
  bool json = false, window_only = false;
  std::vector<std::string> scenarios = {"drone", "urban_vehicle"};
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--seconds") == 0 && i + 1 < argc) {
      seconds = std::stod(argv[++i]);
    } else if (std::strcmp(argv[i], "--scenario") == 0 && i + 1 < argc && (std::strcmp(argv[i + 1], "drone") == 0 || std::strcmp(argv[i + 1], "urban_vehicle") == 0)) {
      scenarios = {argv[++i]};
    } else if (std::strcmp(argv[i], "--json") == 0) {
      json = true;
    } else if (std::strcmp(argv[i], "--window-only") == 0) {
      window_only = true;
    } else {
      std::fprintf(stderr, "usage: bench_memory [--seconds S] [--scenario drone|urban_vehicle] [--json] [--window-only]\n");
      return 2;
    }
  }
  const auto defaults = std::make_unique<hf::pipeline::SessionConfig>();
  const int window = defaults->visual_inertial_window_keyframes;
  nlohmann::json report = nlohmann::json::object();
  for (const std::string& name : scenarios) {
    const bool visual = name == "drone";  // the window applies to the visual-inertial graph
    if (!json) {
      std::printf("| %s %.0f s, %s | resident MB each minute | 2 min -> end | real time | landmarks | loops | map keyframes (revisits) |\n"
                  "|---|---|---|---|---|---|---|\n", name.c_str(),
                  seconds, visual ? "stereo + IMU" : "every sensor, looped");
    }
    for (const int configuration : {window, 0}) {
      if ((window_only || !visual) && configuration != window) continue;
      const Outcome outcome = window_only ? run(name, seconds, configuration) : run_in_child(name, seconds, configuration);
      if (outcome.resident_mb.size() < 2) {
        std::fprintf(stderr, "bench_memory: the %s run with window %d failed\n", name.c_str(), configuration);
        return 1;
      }
      const double growth = outcome.resident_mb.back() / outcome.resident_mb[1] - 1.0;
      const std::string label = !visual ? "defaults" : configuration > 0 ? fmt::format("window {} keyframes", configuration) : "every keyframe kept";
      const double log_seconds = 60.0 * static_cast<double>(outcome.resident_mb.size());
      report[name][label] = {{"resident_mb", outcome.resident_mb}, {"growth_from_2_min", growth}, {"real_time_factor", log_seconds / outcome.seconds},
                             {"landmarks", outcome.landmarks}, {"loop_closures", outcome.loop_closures},
                             {"map_keyframes", outcome.map_keyframes}, {"map_revisits", outcome.map_revisits}};
      if (json) continue;
      std::string minutes;
      for (const double mb : outcome.resident_mb) minutes += fmt::format("{}{:.0f}", minutes.empty() ? "" : " ", mb);
      std::printf("| %s | %s | %+.1f %% | %.2fx | %lu | %lu | %lu (%lu) |\n", label.c_str(), minutes.c_str(), 100.0 * growth,
                  log_seconds / outcome.seconds, static_cast<unsigned long>(outcome.landmarks), static_cast<unsigned long>(outcome.loop_closures),
                  static_cast<unsigned long>(outcome.map_keyframes), static_cast<unsigned long>(outcome.map_revisits));
    }
  }
  if (json) std::printf("%s\n", report.dump().c_str());
  return 0;
}
