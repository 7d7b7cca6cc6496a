// hanzo-fusion: the command-line face of the engine.

#include <iostream>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "argument_hint.hpp"
#include "commands.hpp"
#include "hanzo/fusion/core/logging.hpp"

int main(int argc, char** argv) {
  using namespace hanzo::fusion;
  CLI::App app{"hanzo-fusion: sensor fusion and SLAM engine (HIP-0083)", "hanzo-fusion"};
  app.set_version_flag("--version", std::string("hanzo-fusion ") + HANZO_FUSION_VERSION);
  app.require_subcommand(1);
  app.fallthrough();  // --json and --log-level also work after the subcommand

  app::Output output;
  std::string log_level = "warn";
  app.add_flag("--json", output.json, "Print the result as exactly one JSON object on stdout");
  app.add_option("--log-level", log_level, "Library log level on stderr: trace, debug, info, warn, error, off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}));

  app::Command run;
  app::add_config_command(app, output, run);
  app::add_calib_command(app, output, run);
  app::add_eval_command(app, output, run);
  app::add_log_command(app, output, run);
  app::add_import_command(app, output, run);
  app::add_drive_command(app, output, run);
  app::add_send_command(app, output, run);
  app::add_export_command(app, output, run);
  app::add_sim_command(app, output, run);
  app::add_run_command(app, output, run);
  app::add_graph_command(app, output, run);
  app::add_slam2d_command(app, output, run);
  app::add_lidar_odometry_command(app, output, run);
  app::add_cloud_commands(app, output, run);
  app::add_map_command(app, output, run);
  app::add_privacy_command(app, output, run);
  app::add_crypto_command(app, output, run);
  app::add_features_command(app, output, run);
  app::add_vision_command(app, output, run);
#ifdef HANZO_FUSION_WITH_NEURAL
  app::add_reconstruct_command(app, output, run);
#endif
#ifdef HANZO_FUSION_WITH_SERVICE
  app::add_serve_command(app, output, run);
  app::add_stream_command(app, output, run);
#endif

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& error) {
    if (error.get_exit_code() == 0) return app.exit(error);  // --help, --version
    const std::optional<std::string> hint = app::unknown_argument_hint(app, std::vector<std::string>(argv + 1, argv + argc));
    std::cerr << "hanzo-fusion: " << hint.value_or(error.what()) << " (see hanzo-fusion --help)\n";
    return 2;
  }

  auto logger = spdlog::stderr_color_mt("hanzo_fusion");
  logger->set_level(spdlog::level::from_str(log_level));
  set_logger(logger);
  return run ? run() : 1;
}
