#pragma once
// Whole-file writes that a kill cannot leave half done: the bytes go to "<file>.tmp", which is then
// renamed over the file (atomic on POSIX), so readers see the old file or the new one, never a torn one.
#include <filesystem>
#include <string_view>

namespace sp {

// Throws sp::Error naming the file when it cannot be written.
void write_file_atomically(const std::filesystem::path& file, std::string_view bytes);

}  // namespace sp
