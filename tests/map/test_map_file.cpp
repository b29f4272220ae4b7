// Map files: CRC-32 vectors, a crafted map that survives a round trip field by field, and every way a
// file can be damaged (truncation, flipped bytes, wrong magic or version, dangling ids) refused with a
// message that says what and where.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <filesystem>
#include <fstream>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string_view>

#include "stillpoint/common/error.hpp"
#include "stillpoint/map/map_file.hpp"

namespace sp::map {
namespace {

using namespace sp::map::literals;

std::filesystem::path scratch(const std::string& name) {
  const auto dir = std::filesystem::path(SP_TEST_TMP_DIR) / "map_file";
  std::filesystem::create_directories(dir);
  return dir / name;
}

std::uint32_t crc_of(std::string_view s) {
  return crc32(std::span(reinterpret_cast<const std::uint8_t*>(s.data()), s.size()));
}

TEST(Crc32, KnownVectors) {
  EXPECT_EQ(crc_of(""), 0x00000000U);
  EXPECT_EQ(crc_of("a"), 0xE8B7BE43U);
  EXPECT_EQ(crc_of("123456789"), 0xCBF43926U);
  EXPECT_EQ(crc_of("The quick brown fox jumps over the lazy dog"), 0x414FA339U);
}

TEST(Crc32, ContinuesARunningChecksum) {
  const std::string a = "The quick brown fox ", b = "jumps over the lazy dog";
  EXPECT_EQ(crc32(std::span(reinterpret_cast<const std::uint8_t*>(b.data()), b.size()), crc_of(a)),
            crc_of(a + b));
}

MapFileInfo test_info() {
  MapFileInfo info;
  info.camera.width = 640;
  info.camera.height = 480;
  info.camera.fx = 535.4;
  info.camera.k1 = 0.01;
  info.pyramid_levels = 8;
  info.pyramid_scale_factor = 1.2;
  info.vocabulary_name = "stillpoint_orb.spv";
  info.vocabulary_words = 12345;
  info.vocabulary_checksum = 0x0123456789ABCDEFULL;
  return info;
}

Keyframe make_keyframe(std::mt19937& rng, std::size_t frame, int n, const geo::SE3& T_cw, bool thumbnail) {
  std::uniform_real_distribution<float> u(0.f, 1.f);
  Keyframe kf;
  kf.frame_index = frame;
  kf.stamp = 1000.0 + 0.033 * static_cast<double>(frame);
  kf.T_cw = T_cw;
  auto& f = kf.features;
  f.descriptors = cv::Mat(n, 32, CV_8U);
  cv::randu(f.descriptors, 0, 256);
  for (int i = 0; i < n; ++i) {
    cv::KeyPoint kp(640.f * u(rng), 480.f * u(rng), 31.f * (1.f + u(rng)), 360.f * u(rng), u(rng), i % 8);
    f.keypoints.push_back(kp);
    f.depth.push_back(i % 5 == 0 ? -1.f : 0.5f + 3.f * u(rng));
    f.u_right.push_back(f.depth.back() > 0 ? kp.pt.x - 40.f / f.depth.back() : -1.f);
  }
  kf.index = make_feature_grid(f.keypoints, 640, 480);
  if (thumbnail) {
    kf.thumbnail = cv::Mat(240, 320, CV_8UC3);
    cv::randu(kf.thumbnail, 0, 256);
    cv::GaussianBlur(kf.thumbnail, kf.thumbnail, cv::Size(9, 9), 3.0);  // JPEG-friendly content
  }
  return kf;
}

geo::SE3 pose(double angle, const Eigen::Vector3d& t) {
  return {Eigen::Quaterniond(Eigen::AngleAxisd(angle, Eigen::Vector3d(0.3, -1.0, 0.2).normalized())), t};
}

// A small map with every kind of record and edge: five keyframes (one culled), shared and single-view
// points (one erased), covisibility from update_connections, a spanning tree, a loop edge, thumbnails.
void build_map(Map& map) {
  std::mt19937 rng(7);
  MapView v = map.view();
  std::vector<KeyframeId> kfs;
  for (int k = 0; k < 5; ++k) {
    kfs.push_back(v.add_keyframe(make_keyframe(rng, static_cast<std::size_t>(10 * k), 60 + k,
                                               pose(0.1 * k, {0.05 * k, -0.01 * k, 0.02}), k != 2)));
  }
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 50; ++i) {
    MapPoint p;
    p.position = {u(rng), u(rng), 2.0 + u(rng)};
    p.descriptor = v.keyframe(kfs[0])->features.descriptors.row(i).clone();
    p.visible = 3 + i;
    p.found = 2 + i / 2;
    p.reference = kfs[0];
    p.first_keyframe = kfs[0];
    const PointId pid = v.add_point(std::move(p));
    v.add_observation(pid, kfs[0], i);
    // Most points are seen by the next keyframes too, so covisibility edges pass the threshold.
    for (std::size_t k = 1; k < kfs.size(); ++k) {
      if ((i + static_cast<int>(k)) % 4 != 0) v.add_observation(pid, kfs[k], i + static_cast<int>(k));
    }
    v.update_point_normal_and_depth(pid, ScalePyramid::make(8, 1.2));
  }
  for (KeyframeId k : kfs) v.update_connections(k);
  v.keyframe(kfs[4])->loop_edges.insert(kfs[0]);
  v.keyframe(kfs[0])->loop_edges.insert(kfs[4]);
  v.erase_point(7_pt);                            // bad point: not saved
  v.erase_keyframe(kfs[3]);                       // culled keyframe: not saved, its child is re-parented
  v.keyframe(kfs[4])->loop_edges.insert(kfs[3]);  // an edge into a culled keyframe is dropped on save
}

void expect_same_pose(const geo::SE3& a, const geo::SE3& b) {
  EXPECT_LT((a.translation() - b.translation()).norm(), 1e-15);
  EXPECT_LT(a.quaternion().angularDistance(b.quaternion()), 1e-12);
}

TEST(MapFile, RoundTripKeepsEveryField) {
  Map map;
  build_map(map);
  const auto file = scratch("roundtrip.spmap");
  const MapSaveResult saved = save_map(map, file, test_info());
  EXPECT_EQ(saved.keyframes, 4U);
  EXPECT_EQ(saved.points, 49U);
  EXPECT_EQ(saved.bytes, std::filesystem::file_size(file));
  EXPECT_FALSE(std::filesystem::exists(file.string() + ".tmp"));

  Map loaded;
  const MapFileInfo info = load_map(file, loaded);
  EXPECT_TRUE(info == test_info());

  MapView a = map.view();
  MapView b = loaded.view();
  EXPECT_EQ(a.next_ids(), b.next_ids());
  EXPECT_EQ(b.live_keyframes(), a.live_keyframes());
  EXPECT_EQ(b.live_points(), a.live_points());
  EXPECT_EQ(b.keyframes().size(), 4U);  // the culled keyframe is not in the file
  // The crafted map exercises every kind of edge (so the comparisons below compare something).
  std::size_t covis = 0, loops = 0, children = 0, thumbs = 0;
  for (const auto& [id, kf] : b.keyframes()) {
    covis += kf.covisibility.size();
    loops += kf.loop_edges.size();
    children += kf.children.size();
    thumbs += kf.thumbnail.empty() ? 0 : 1;
  }
  EXPECT_GE(covis, 6U);
  EXPECT_EQ(loops, 2U);
  EXPECT_EQ(children, 3U);
  EXPECT_EQ(thumbs, 3U);
  for (KeyframeId id : a.keyframe_ids_sorted()) {
    SCOPED_TRACE("keyframe " + std::to_string(id.value()));
    const Keyframe& x = *a.keyframe(id);
    const Keyframe* y = b.keyframe(id);
    ASSERT_NE(y, nullptr);
    EXPECT_EQ(y->frame_index, x.frame_index);
    EXPECT_EQ(y->stamp, x.stamp);
    expect_same_pose(y->T_cw, x.T_cw);
    ASSERT_EQ(y->features.size(), x.features.size());
    for (std::size_t i = 0; i < x.features.size(); ++i) {
      const auto &p = x.features.keypoints[i], &q = y->features.keypoints[i];
      EXPECT_EQ(q.pt, p.pt);
      EXPECT_EQ(q.octave, p.octave);
      EXPECT_EQ(q.angle, p.angle);
      EXPECT_EQ(q.size, p.size);
      EXPECT_EQ(q.response, p.response);
    }
    EXPECT_EQ(y->features.depth, x.features.depth);
    EXPECT_EQ(y->features.u_right, x.features.u_right);
    EXPECT_EQ(cv::norm(y->features.descriptors, x.features.descriptors, cv::NORM_L1), 0.0);
    EXPECT_EQ(y->points, x.points);
    EXPECT_EQ(y->covisibility, x.covisibility);
    EXPECT_EQ(y->parent, x.parent);
    EXPECT_EQ(y->children, x.children);
    std::set<KeyframeId> live_loops;
    for (KeyframeId l : x.loop_edges) {
      if (!a.keyframe(l)->bad) live_loops.insert(l);
    }
    EXPECT_EQ(y->loop_edges, live_loops);
    EXPECT_EQ(y->index.size(), x.features.size());
    ASSERT_EQ(y->thumbnail.empty(), x.thumbnail.empty());
    if (!x.thumbnail.empty()) {
      ASSERT_EQ(y->thumbnail.size(), x.thumbnail.size());
      ASSERT_EQ(y->thumbnail.type(), x.thumbnail.type());
      // JPEG is lossy: close on average, not bit-exact.
      EXPECT_LT(
          cv::norm(y->thumbnail, x.thumbnail, cv::NORM_L1) / static_cast<double>(x.thumbnail.total() * 3),
          4.0);
    }
  }
  for (const auto& [id, p] : a.points()) {
    if (p.bad) {
      EXPECT_EQ(b.point(id), nullptr);
      continue;
    }
    SCOPED_TRACE("point " + std::to_string(id.value()));
    const MapPoint* q = b.point(id);
    ASSERT_NE(q, nullptr);
    EXPECT_EQ(q->position, p.position);
    EXPECT_EQ(cv::norm(q->descriptor, p.descriptor, cv::NORM_L1), 0.0);
    EXPECT_EQ(q->normal, p.normal);
    EXPECT_EQ(q->min_distance, p.min_distance);
    EXPECT_EQ(q->max_distance, p.max_distance);
    EXPECT_EQ(q->observations, p.observations);
    EXPECT_EQ(q->reference, p.reference);
    EXPECT_EQ(q->first_keyframe, p.first_keyframe);
    EXPECT_EQ(q->visible, p.visible);
    EXPECT_EQ(q->found, p.found);
    EXPECT_FALSE(q->bad);
  }
}

TEST(MapFile, KeyframesKeepTheirMapIds) {
  Map map;
  build_map(map);
  std::mt19937 rng(11);
  KeyframeId root = kNoKeyframe, child = kNoKeyframe;
  {
    // A second map, not merged: its own root and a child, no edge to map 0.
    MapView v = map.view();
    Keyframe a = make_keyframe(rng, 200, 40, pose(1.0, {3.0, 0.0, 0.0}), false);
    a.map_id = MapId{1};
    root = v.add_keyframe(std::move(a));
    Keyframe b = make_keyframe(rng, 210, 40, pose(1.1, {3.1, 0.0, 0.0}), false);
    b.map_id = MapId{1};
    child = v.add_keyframe(std::move(b));
    v.keyframe(child)->parent = root;
    v.keyframe(root)->children.insert(child);
  }
  const auto file = scratch("two_maps.spmap");
  save_map(map, file, test_info());
  Map loaded;
  load_map(file, loaded);
  MapReader a = map.reader(), b = loaded.reader();
  EXPECT_EQ(b.live_maps().size(), 2u);
  for (KeyframeId id : a.keyframe_ids_sorted())
    EXPECT_EQ(b.keyframe(id)->map_id, a.keyframe(id)->map_id) << id;
  EXPECT_EQ(b.keyframe(child)->parent, root);
  EXPECT_EQ(b.map_root(MapId{1}), root);
}

TEST(MapFile, LoadedMapGrowsWithFreshIds) {
  Map map;
  build_map(map);
  const auto file = scratch("grow.spmap");
  save_map(map, file, test_info());
  Map loaded;
  load_map(file, loaded);
  const auto [next_kf, next_pt] = map.view().next_ids();
  MapView v = loaded.view();
  std::mt19937 rng(3);
  EXPECT_EQ(v.add_keyframe(make_keyframe(rng, 99, 10, geo::SE3(), false)), next_kf);
  EXPECT_EQ(v.add_point(MapPoint{}), next_pt);
}

TEST(MapFile, LoadIntoANonEmptyMapIsRefused) {
  Map map;
  build_map(map);
  const auto file = scratch("nonempty.spmap");
  save_map(map, file, test_info());
  EXPECT_THROW(load_map(file, map), Error);
}

std::vector<std::uint8_t> saved_bytes(const std::string& name) {
  Map map;
  build_map(map);
  const auto file = scratch(name);
  save_map(map, file, test_info());
  std::ifstream in(file, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Offsets of the four sections (tag position), walked from the framing.
std::vector<std::size_t> section_offsets(const std::vector<std::uint8_t>& b) {
  std::vector<std::size_t> out;
  std::size_t pos = 12;
  while (pos + 12 <= b.size()) {
    out.push_back(pos);
    std::uint64_t len = 0;
    for (std::size_t i = 0; i < 8; ++i) len |= std::uint64_t{b[pos + 4 + i]} << (8 * i);
    pos += 12 + len + 4;
  }
  return out;
}

std::string parse_error(const std::vector<std::uint8_t>& bytes, const std::string& name = "damaged.spmap") {
  try {
    parse_map(bytes, name);
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), name);
    return e.what();
  }
  ADD_FAILURE() << "the damaged file was accepted";
  return {};
}

TEST(MapFile, TruncatedFileNamesOffsetAndSection) {
  const auto bytes = saved_bytes("trunc.spmap");
  const auto sections = section_offsets(bytes);
  ASSERT_EQ(sections.size(), 4U);
  struct Cut {
    std::size_t at;
    const char* section;
  };
  const std::vector<Cut> cuts = {{10, "header"},
                                 {sections[0] + 5, "HEAD"},
                                 {sections[0] + 40, "HEAD"},
                                 {sections[1] + 2000, "KFRM"},
                                 {sections[2] - 1, "KFRM"},
                                 {sections[2] + 300, "MPNT"},
                                 {sections[3] + 3, "END"},
                                 {bytes.size() - 1, "END"}};
  for (const Cut& c : cuts) {
    SCOPED_TRACE("cut at " + std::to_string(c.at));
    const std::vector<std::uint8_t> cut(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(c.at));
    const std::string msg = parse_error(cut);
    EXPECT_NE(msg.find("damaged.spmap"), std::string::npos) << msg;
    EXPECT_NE(msg.find("truncated at byte offset " + std::to_string(c.at)), std::string::npos) << msg;
    EXPECT_NE(msg.find(c.section), std::string::npos) << msg;
  }
}

TEST(MapFile, FlippedByteIsAChecksumErrorNamingTheSection) {
  const auto bytes = saved_bytes("flip.spmap");
  const auto sections = section_offsets(bytes);
  ASSERT_EQ(sections.size(), 4U);
  const std::vector<std::pair<std::size_t, std::string>> flips = {{sections[0] + 20, "section HEAD"},
                                                                  {sections[1] + 500, "section KFRM"},
                                                                  {sections[2] - 10, "section KFRM"},
                                                                  {sections[2] + 100, "section MPNT"},
                                                                  {sections[3] + 14, "section END"}};
  for (const auto& [at, section] : flips) {
    auto damaged = bytes;
    damaged[at] ^= 0x10;
    const std::string msg = parse_error(damaged);
    EXPECT_NE(msg.find("checksum mismatch in " + section), std::string::npos) << msg;
  }
}

TEST(MapFile, WrongMagicIsNotAMapFile) {
  auto bytes = saved_bytes("magic.spmap");
  bytes[0] = 'X';
  EXPECT_NE(parse_error(bytes).find("not a StillPoint map file"), std::string::npos);
  EXPECT_NE(parse_error({}).find("not a StillPoint map file"), std::string::npos);
  const std::string text = "# TUM trajectory\n1.0 0 0 0 0 0 0 1\n";
  EXPECT_NE(
      parse_error(std::vector<std::uint8_t>(text.begin(), text.end())).find("not a StillPoint map file"),
      std::string::npos);
}

TEST(MapFile, OtherVersionStatesBothVersions) {
  auto bytes = saved_bytes("version.spmap");
  bytes[8] = 7;
  const std::string msg = parse_error(bytes);
  EXPECT_NE(msg.find("format version 7"), std::string::npos) << msg;
  EXPECT_NE(msg.find("reads version " + std::to_string(kMapFormatVersion)), std::string::npos) << msg;
}

TEST(MapFile, MissingFileIsAnInputError) {
  Map map;
  EXPECT_THROW(load_map(scratch("does_not_exist.spmap"), map), InputError);
}

MapContents crafted() {
  Map map;
  build_map(map);
  return snapshot_map(map, test_info());
}

TEST(MapFile, DanglingIdsAreRejected) {
  {
    MapContents m = crafted();
    const auto it = std::find(m.keyframes[0].points.begin(), m.keyframes[0].points.end(), kNoPoint);
    ASSERT_NE(it, m.keyframes[0].points.end());
    const PointId last_handed_out{m.next_point_id.value() - 1};
    *it = last_handed_out == m.points.back().id ? PointId{m.points.back().id.value() + 100} : last_handed_out;
    m.next_point_id = PointId{it->value() + 1};
    EXPECT_NE(parse_error(serialize_map(m)).find("references missing point"), std::string::npos);
  }
  {
    MapContents m = crafted();
    m.keyframes[1].covisibility[4000_kf] = 20;
    m.next_keyframe_id = 5000_kf;
    EXPECT_NE(parse_error(serialize_map(m)).find("covisibility edge to missing keyframe 4000"),
              std::string::npos);
  }
  {
    MapContents m = crafted();
    m.keyframes[2].parent = 4_kf;  // keyframe 4 was culled
    EXPECT_NE(parse_error(serialize_map(m)).find("missing spanning-tree parent 4"), std::string::npos);
  }
  {
    MapContents m = crafted();
    ASSERT_NE(m.keyframes[2].parent, kNoKeyframe);
    m.keyframes[2].map_id = MapId{1};  // its parent stays in map 0
    EXPECT_NE(parse_error(serialize_map(m)).find("in map 0"), std::string::npos);
  }
  {
    MapContents m = crafted();
    m.points[0].observations[4_kf] = 0;
    EXPECT_NE(parse_error(serialize_map(m)).find("observed by missing keyframe 4"), std::string::npos);
  }
  {
    MapContents m = crafted();
    m.points[3].reference = 4_kf;
    EXPECT_NE(parse_error(serialize_map(m)).find("reference keyframe 4"), std::string::npos);
  }
}

// The fuzzer's seeds must stay valid files of this build's format (a version bump regenerates them),
// or the fuzzer only ever exercises the version check.
TEST(MapFile, FuzzSeedsAreValidFilesOfThisVersion) {
  const auto dir = std::filesystem::path(SP_SOURCE_DIR) / "fuzz" / "corpus" / "fuzz_map_file";
  int seeds = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    std::ifstream in(entry.path(), std::ios::binary);
    const std::vector<std::uint8_t> file((std::istreambuf_iterator<char>(in)),
                                         std::istreambuf_iterator<char>());
    ASSERT_GT(file.size(), 1u) << entry.path();
    std::vector<std::uint8_t> bytes(file.begin() + 1, file.end());  // the first byte picks the fuzzer's mode
    EXPECT_NO_THROW(parse_map(bytes, entry.path().string())) << entry.path();
    ++seeds;
  }
  EXPECT_GE(seeds, 2);
}

TEST(MapFile, ResealedStructuralDamageIsStillRejected) {
  // A file whose checksums were recomputed after damage reaches the record checks.
  auto bytes = saved_bytes("reseal.spmap");
  const auto sections = section_offsets(bytes);
  auto ok = bytes;
  reseal_map_bytes(ok);
  EXPECT_EQ(ok, bytes);  // resealing an intact file changes nothing
  EXPECT_NO_THROW(parse_map(ok, "ok.spmap"));
  // First keyframe record: u32 count, id, frame, stamp, u32 map id, 7 pose doubles, u32 n, then the
  // first feature; its octave is the sixth 4-byte field.
  const std::size_t octave_at = sections[1] + 12 + 4 + 8 + 8 + 8 + 4 + 56 + 4 + 20;
  bytes[octave_at] = 99;
  reseal_map_bytes(bytes);
  const std::string msg = parse_error(bytes);
  EXPECT_NE(msg.find("octave 99 outside the pyramid"), std::string::npos) << msg;
  EXPECT_NE(msg.find("section KFRM at byte offset"), std::string::npos) << msg;
}

}  // namespace
}  // namespace sp::map
