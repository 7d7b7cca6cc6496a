// Memory of a long visual-inertial session (issue: "resident size after 10 minutes within 10 % of
// that after 2 minutes"): the simulated drone's figure eights (examples/scenarios/drone.yaml,
// stereo cameras + IMU, its trajectory made `--seconds` long) streamed straight from the
// simulator into a Session as the server runs one (frontend msckf with the visual-inertial graph,
// loop closure on, no trajectory kept), resident memory sampled every 60 s of log. Each
// configuration runs in a fresh process: the session's sliding window (the default) and every
// keyframe's variables kept (visual_inertial_window_keyframes 0, the graph before the window).
//
//   build/bench/bench_memory [--seconds 600] [--json]
//
// Reports per configuration: resident MB at each minute, growth from 2 min to the end, real-time
// factor (simulation included: it renders the images), landmarks and loop closures.
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
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
};

Outcome run(double seconds, int window) {
  hf::sim::Scenario scenario = hf::sim::load_scenario(std::string(HANZO_SOURCE_DIR) + "/examples/scenarios/drone.yaml").value();
  scenario.drone.duration = seconds;
  scenario.num_threads = 0;
  auto simulation = hf::sim::ScenarioSimulation::create(scenario).value();
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
  return outcome;
}

// run() in a child process (each configuration from a fresh heap), its outcome through a pipe.
Outcome run_in_child(double seconds, int window) {
  int pipe_ends[2];
  if (::pipe(pipe_ends) != 0) return {};
  const pid_t child = ::fork();
  if (child == 0) {
    ::close(pipe_ends[0]);
    const Outcome outcome = run(seconds, window);
    const std::string text = nlohmann::json{{"resident_mb", outcome.resident_mb}, {"seconds", outcome.seconds}, {"landmarks", outcome.landmarks},
                                            {"loop_closures", outcome.loop_closures}}.dump();
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
  return outcome;
}

}  // namespace

int main(int argc, char** argv) {
  double seconds = 600.0;
  bool json = false;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--seconds") == 0 && i + 1 < argc) {
      seconds = std::stod(argv[++i]);
    } else if (std::strcmp(argv[i], "--json") == 0) {
      json = true;
    } else {
      std::fprintf(stderr, "usage: bench_memory [--seconds S] [--json]\n");
      return 2;
    }
  }
  const auto defaults = std::make_unique<hf::pipeline::SessionConfig>();
  const int window = defaults->visual_inertial_window_keyframes;
  nlohmann::json report = nlohmann::json::object();
  if (!json) std::printf("| drone %.0f s, stereo + IMU | resident MB each minute | 2 min -> end | real time | landmarks | loops |\n|---|---|---|---|---|---|\n", seconds);
  for (const int configuration : {window, 0}) {
    const Outcome outcome = run_in_child(seconds, configuration);
    if (outcome.resident_mb.size() < 2) {
      std::fprintf(stderr, "bench_memory: the run with window %d failed\n", configuration);
      return 1;
    }
    const double growth = outcome.resident_mb.back() / outcome.resident_mb[1] - 1.0;
    const std::string name = configuration > 0 ? fmt::format("window {} keyframes", configuration) : "every keyframe kept";
    report[name] = {{"resident_mb", outcome.resident_mb}, {"growth_from_2_min", growth}, {"real_time_factor", seconds / outcome.seconds},
                    {"landmarks", outcome.landmarks}, {"loop_closures", outcome.loop_closures}};
    if (json) continue;
    std::string minutes;
    for (const double mb : outcome.resident_mb) minutes += fmt::format("{}{:.0f}", minutes.empty() ? "" : " ", mb);
    std::printf("| %s | %s | %+.1f %% | %.2fx | %lu | %lu |\n", name.c_str(), minutes.c_str(), 100.0 * growth, seconds / outcome.seconds,
                static_cast<unsigned long>(outcome.landmarks), static_cast<unsigned long>(outcome.loop_closures));
  }
  if (json) std::printf("%s\n", report.dump().c_str());
  return 0;
}
