#pragma once
// Where StillPoint's data lives at run time (config/, data/vocab, data/demo, models/): never the
// compiled-in source directory, so an installed binary or library works with the source tree gone.
//
// Looked up in this order:
//   1. $STILLPOINT_DATA_DIR (must hold config/stillpoint.yaml, else an sp::Error naming it);
//   2. share/stillpoint next to an anchor file (the running binary, or libstillpoint.so) or next to one
//      of its parent folders, up to five levels up: <prefix>/bin/stillpoint and
//      <prefix>/lib[/<arch>]/libstillpoint.so find <prefix>/share/stillpoint after `cmake --install`; in a
//      build tree the configure step links <build>/share/stillpoint to the source tree's folders.
#include <filesystem>
#include <optional>

namespace sp {

// The folder's marker: a data folder holds the default configuration.
inline constexpr const char* kDataMarker = "config/stillpoint.yaml";

// share/stillpoint in `anchor`'s folder or one of its parents (at most `levels` up), if any.
std::optional<std::filesystem::path> find_data_dir_near(const std::filesystem::path& anchor, int levels = 5);

// The data folder for a program or library at `anchor` (see above). Throws sp::Error with what to do
// when there is none.
std::filesystem::path resolve_data_dir(const std::filesystem::path& anchor);

// The running executable (/proc/self/exe).
std::filesystem::path current_executable();

}  // namespace sp
