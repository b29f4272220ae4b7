#include "stillpoint/common/data_dir.hpp"

#include <cstdlib>
#include <system_error>

#include "stillpoint/common/error.hpp"

namespace sp {

namespace fs = std::filesystem;

std::optional<fs::path> find_data_dir_near(const fs::path& anchor, int levels) {
  std::error_code ec;
  fs::path dir = fs::weakly_canonical(anchor, ec);
  if (ec) dir = anchor;
  if (!fs::is_directory(dir, ec)) dir = dir.parent_path();
  for (int i = 0; i <= levels && !dir.empty(); ++i) {
    const fs::path candidate = dir / "share" / "stillpoint";
    if (fs::exists(candidate / kDataMarker, ec)) return candidate;
    if (dir == dir.parent_path()) break;
    dir = dir.parent_path();
  }
  return std::nullopt;
}

fs::path resolve_data_dir(const fs::path& anchor) {
  if (const char* env = std::getenv("STILLPOINT_DATA_DIR"); env != nullptr && *env != '\0') {
    const fs::path dir(env);
    std::error_code ec;
    if (!fs::exists(dir / kDataMarker, ec)) {
      throw Error("STILLPOINT_DATA_DIR=" + dir.string() + " is not a StillPoint data folder (no " +
                  std::string(kDataMarker) + " in it)");
    }
    return dir;
  }
  if (auto dir = find_data_dir_near(anchor)) return *dir;
  throw Error("cannot find StillPoint's data folder (config/, data/, models/) near " + anchor.string() +
              ": expected <prefix>/share/stillpoint beside the installed binary or library; set "
              "STILLPOINT_DATA_DIR to that folder (or to the source tree's root)");
}

fs::path current_executable() {
  std::error_code ec;
  fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : exe;
}

}  // namespace sp
