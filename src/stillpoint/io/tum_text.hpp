#pragma once
// Parser for the TUM RGB-D text lists (rgb.txt, depth.txt, associations.txt, groundtruth.txt):
// whitespace- (or comma-) separated columns, the first a timestamp; '#' comments and blank lines skipped.
#include <filesystem>
#include <string>
#include <vector>

namespace sp::io {

struct TextRecord {
  int line = 0;                      // 1-based line in the file
  double stamp = 0;                  // first column
  std::vector<std::string> columns;  // all columns, the timestamp included
};

// Reads every record and checks that each has exactly `columns` columns (0 = any count >= 2), that
// the first column is a number and that timestamps strictly increase. Errors are sp::InputError
// naming the file and line.
std::vector<TextRecord> read_tum_text(const std::filesystem::path& file, std::size_t columns);

// A list of `timestamp path` lines (rgb.txt, depth.txt).
struct StampedPath {
  double stamp = 0;
  std::string path;
};
std::vector<StampedPath> read_tum_file_list(const std::filesystem::path& file);

// Parses a whole string as a finite double; false when anything is left over.
bool parse_double(const std::string& text, double& value);

}  // namespace sp::io
