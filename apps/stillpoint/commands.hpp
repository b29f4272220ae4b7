#pragma once
// Each subcommand lives in its own cmd_<name>.cpp and registers itself on the CLI11 app.
// A subcommand is compiled only when the module it needs is part of the build.
#include <CLI/CLI.hpp>

namespace sp::app {
void add_eval_command(CLI::App& app);
void add_run_command(CLI::App& app);
void add_bench_command(CLI::App& app);
void add_vocab_command(CLI::App& app);
void add_vpr_command(CLI::App& app);
void add_report_command(CLI::App& app);
}  // namespace sp::app
