// stillpoint: RGB-D SLAM for scenes with moving people. One program, one subcommand per job.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <exception>

#include "commands.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/common/logging.hpp"
#include "stillpoint/version.hpp"
#ifdef SP_HAVE_CMD_RUN
#include "stillpoint/stillpoint.hpp"
#endif

int main(int argc, char** argv) {
  CLI::App app{"StillPoint: RGB-D visual SLAM that keeps only the still points"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("stillpoint ") + STILLPOINT_VERSION +
                                        (SP_WITH_TORCH ? " (with libtorch: netvlad, vpr)"
                                                       : " (without libtorch: no netvlad, no vpr)"));
  std::string log_level = "info";
  app.add_option("--log-level", log_level, "trace|debug|info|warn|error|off")->capture_default_str();
#ifdef SP_HAVE_CMD_EVAL
  sp::app::add_eval_command(app);
#endif
#ifdef SP_HAVE_CMD_RUN
  sp::app::add_run_command(app);
#endif
#ifdef SP_HAVE_CMD_BENCH
  sp::app::add_bench_command(app);
#endif
#ifdef SP_HAVE_CMD_VOCAB
  sp::app::add_vocab_command(app);
#endif
#ifdef SP_HAVE_CMD_VPR
  sp::app::add_vpr_command(app);
#endif
#ifdef SP_HAVE_CMD_REPORT
  sp::app::add_report_command(app);
#endif
  app.parse_complete_callback([&] { sp::setup_logging(log_level); });
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const sp::Error& e) {
    spdlog::error("{}", e.what());
    return 2;
#ifdef SP_HAVE_CMD_RUN
  } catch (const stillpoint::Error& e) {  // `run` goes through the public API, which has its own type
    spdlog::error("{}", e.what());
    return 2;
#endif
  } catch (const std::exception& e) {
    spdlog::error("unexpected error: {}", e.what());
    return 3;
  }
  return 0;
}
