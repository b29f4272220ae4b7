#include "stillpoint/io/tum_text.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

#include "stillpoint/common/error.hpp"

namespace sp::io {

bool parse_double(const std::string& text, double& value) {
  if (text.empty()) return false;
  try {
    std::size_t used = 0;
    value = std::stod(text, &used);
    return used == text.size() && std::isfinite(value);
  } catch (const std::exception&) {
    return false;
  }
}

std::vector<TextRecord> read_tum_text(const std::filesystem::path& file, std::size_t columns) {
  std::ifstream in(file);
  if (!in) throw InputError(file.string(), 0, "cannot open file");
  std::vector<TextRecord> records;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    // Like associate.py: commas and tabs separate columns too.
    for (char& c : line) {
      if (c == ',' || c == '\t') c = ' ';
    }
    const auto first = line.find_first_not_of(' ');
    if (first == std::string::npos || line[first] == '#') continue;
    TextRecord rec;
    rec.line = line_no;
    std::istringstream fields(line);
    std::string f;
    while (fields >> f) rec.columns.push_back(f);
    if (columns != 0 && rec.columns.size() != columns) {
      throw InputError(
          file.string(), line_no,
          "expected " + std::to_string(columns) + " columns, found " + std::to_string(rec.columns.size()));
    }
    if (columns == 0 && rec.columns.size() < 2) {
      throw InputError(file.string(), line_no, "expected a timestamp and at least one more column");
    }
    if (!parse_double(rec.columns[0], rec.stamp)) {
      throw InputError(file.string(), line_no, "timestamp '" + rec.columns[0] + "' is not a number");
    }
    if (!records.empty() && rec.stamp <= records.back().stamp) {
      throw InputError(file.string(), line_no,
                       "timestamp " + rec.columns[0] + " is not after the previous one (line " +
                           std::to_string(records.back().line) + "): timestamps must increase");
    }
    records.push_back(std::move(rec));
  }
  return records;
}

std::vector<StampedPath> read_tum_file_list(const std::filesystem::path& file) {
  std::vector<StampedPath> out;
  for (auto& rec : read_tum_text(file, 2)) out.push_back({rec.stamp, std::move(rec.columns[1])});
  return out;
}

}  // namespace sp::io
