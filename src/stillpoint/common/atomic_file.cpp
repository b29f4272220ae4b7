#include "stillpoint/common/atomic_file.hpp"

#include <fstream>
#include <string>

#include "stillpoint/common/error.hpp"

namespace sp {

void write_file_atomically(const std::filesystem::path& file, std::string_view bytes) {
  const std::filesystem::path tmp = file.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw Error("cannot write " + file.string());
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    out.close();
    if (!out) throw Error("cannot write " + file.string());
  }
  std::filesystem::rename(tmp, file);
}

}  // namespace sp
