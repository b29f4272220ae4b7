// libFuzzer target: the binary map file (map/map_file). Two modes, chosen by the first byte:
//  even: the rest is the file image as is (magic, version, framing and checksum checks);
//  odd:  the rest gets its section checksums recomputed first (reseal_map_bytes), so mutations of a
//        valid seed reach the record parser and the cross-reference checks behind the CRCs.
// Every rejection must be an sp::Error. A map that loads must restore into a Map and survive another
// save/parse round trip with the same record counts.
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "stillpoint/common/error.hpp"
#include "stillpoint/map/map_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  std::vector<std::uint8_t> bytes(data + 1, data + size);
  if ((data[0] & 1U) != 0) sp::map::reseal_map_bytes(bytes);
  sp::map::MapContents contents;
  try {
    contents = sp::map::parse_map(bytes, "fuzz.spmap");
  } catch (const sp::Error&) {
    return 0;
  }
  const std::size_t keyframes = contents.keyframes.size();
  const std::size_t points = contents.points.size();
  sp::map::Map map;
  {
    sp::map::MapView view = map.view();
    view.restore(std::move(contents.keyframes), std::move(contents.points), contents.next_keyframe_id,
                 contents.next_point_id);
  }
  const auto again = sp::map::serialize_map(sp::map::snapshot_map(map, contents.info));
  const auto reparsed = sp::map::parse_map(again, "fuzz-resaved.spmap");  // throws (a finding) if invalid
  if (reparsed.keyframes.size() != keyframes || reparsed.points.size() != points) std::abort();
  return 0;
}
