#include "stillpoint/map/map_file.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <unordered_map>
#include <unordered_set>

#include "stillpoint/common/error.hpp"
#include "stillpoint/map/byte_codec.hpp"

namespace sp::map {

namespace {

constexpr std::array<char, 8> kMagic = {'S', 'P', 'M', 'A', 'P', 'B', 'I', 'N'};
constexpr std::size_t kPreambleBytes = 12;  // magic + version
constexpr std::size_t kFrameBytes = 16;     // tag + length + crc around each payload
constexpr int kDescBytes = 32;
// The smallest records, for the count checks before reading. A keyframe: id, frame index, stamp, map
// id, pose, feature / covisibility / loop-edge counts, parent, thumbnail length. A point: id, position,
// descriptor, normal, distance range, reference and creating keyframes, counters, observation count and
// its one required observation (a bound of 160 once refused valid maps of single-view points).
constexpr std::size_t kMinKeyframeBytes = 8 + 8 + 8 + 4 + 7 * 8 + 4 + 4 + 4 + 8 + 4;
constexpr std::size_t kMinPointBytes = 8 + 3 * 8 + kDescBytes + 3 * 8 + 2 * 8 + 2 * 8 + 2 * 4 + 4 + 12;
// Bounds that keep a corrupt (but well-sealed) file from asking for absurd allocations.
constexpr int kMaxImageSide = 16384;
constexpr int kMaxThumbnailSide = 4096;
constexpr int kMaxPyramidLevels = 32;

constexpr std::uint32_t tag_of(const char (&s)[5]) {
  return static_cast<std::uint32_t>(static_cast<unsigned char>(s[0])) |
         static_cast<std::uint32_t>(static_cast<unsigned char>(s[1])) << 8U |
         static_cast<std::uint32_t>(static_cast<unsigned char>(s[2])) << 16U |
         static_cast<std::uint32_t>(static_cast<unsigned char>(s[3])) << 24U;
}
constexpr std::uint32_t kTagHead = tag_of("HEAD");
constexpr std::uint32_t kTagKeyframes = tag_of("KFRM");
constexpr std::uint32_t kTagPoints = tag_of("MPNT");
constexpr std::uint32_t kTagEnd = tag_of("END ");

std::string tag_name(std::uint32_t tag) {
  std::string s;
  for (int i = 0; i < 4; ++i) {
    const auto c = static_cast<char>((tag >> (8U * static_cast<unsigned>(i))) & 0xFFU);
    s += (c >= 0x20 && c < 0x7F) ? c : '?';
  }
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s;
}

// ---------------------------------------------------------------- writing

void append_section(std::vector<std::uint8_t>& out, std::uint32_t tag,
                    const std::vector<std::uint8_t>& payload) {
  ByteWriter w;
  w.u32(tag);
  w.u64(payload.size());
  auto& b = w.buffer();
  b.insert(b.end(), payload.begin(), payload.end());
  const std::uint32_t crc = crc32(b);
  w.u32(crc);
  out.insert(out.end(), b.begin(), b.end());
}

void write_pose(ByteWriter& w, const geo::SE3& T) {
  const Eigen::Quaterniond& q = T.quaternion();
  w.f64(q.x());
  w.f64(q.y());
  w.f64(q.z());
  w.f64(q.w());
  w.vec3(T.translation());
}

void write_descriptor(ByteWriter& w, const cv::Mat& desc, int row) {
  std::array<std::uint8_t, kDescBytes> d{};
  if (!desc.empty() && desc.type() == CV_8U && desc.cols == kDescBytes && row < desc.rows)
    std::memcpy(d.data(), desc.ptr<std::uint8_t>(row), kDescBytes);
  w.bytes(d.data(), d.size());
}

std::vector<std::uint8_t> encode_thumbnail(const cv::Mat& thumbnail) {
  std::vector<std::uint8_t> jpeg;
  if (thumbnail.empty()) return jpeg;
  // Quality 85: a 320x240 thumbnail is ~10-15 kB, enough for place recognition and reports.
  if (!cv::imencode(".jpg", thumbnail, jpeg, {cv::IMWRITE_JPEG_QUALITY, 85})) jpeg.clear();
  return jpeg;
}

// ---------------------------------------------------------------- reading

geo::SE3 read_pose(ByteReader& r) {
  Eigen::Quaterniond q;
  q.x() = r.finite64("pose quaternion");
  q.y() = r.finite64("pose quaternion");
  q.z() = r.finite64("pose quaternion");
  q.w() = r.finite64("pose quaternion");
  if (std::abs(q.norm() - 1.0) > 1e-6)
    r.fail(fmt::format("pose quaternion has norm {} (not a rotation)", q.norm()));
  const Eigen::Vector3d t = r.vec3("pose translation");
  return {q, t};
}

// Width and height from a JPEG's start-of-frame marker, so a corrupt header cannot make the decoder
// allocate gigabytes; nullopt when there is no frame header before the scan.
std::optional<cv::Size> jpeg_size(std::span<const std::uint8_t> j) {
  if (j.size() < 4 || j[0] != 0xFF || j[1] != 0xD8) return std::nullopt;
  std::size_t i = 2;
  while (i + 4 <= j.size()) {
    if (j[i] != 0xFF) return std::nullopt;
    const std::uint8_t marker = j[i + 1];
    if (marker == 0xFF) {  // fill byte
      ++i;
      continue;
    }
    const std::size_t len = std::size_t{j[i + 2]} << 8U | j[i + 3];
    if (len < 2) return std::nullopt;
    const bool sof = marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
    if (sof) {
      if (i + 9 > j.size()) return std::nullopt;
      const int h = j[i + 5] << 8 | j[i + 6];
      const int w = j[i + 7] << 8 | j[i + 8];
      return cv::Size(w, h);
    }
    if (marker == 0xDA) return std::nullopt;  // scan before any frame header
    i += 2 + len;
  }
  return std::nullopt;
}

MapFileInfo read_head(ByteReader& r, std::uint64_t& n_keyframes, std::uint64_t& n_points, KeyframeId& next_kf,
                      PointId& next_pt) {
  MapFileInfo info;
  n_keyframes = r.u64();
  n_points = r.u64();
  next_kf = r.id<KeyframeId>();
  next_pt = r.id<PointId>();
  if (next_kf == kNoKeyframe || next_pt == kNoPoint) r.fail("id counters must be at least 1");
  if (n_keyframes >= next_kf.value() || n_points >= next_pt.value())
    r.fail("more records than ids handed out");
  auto& c = info.camera;
  c.width = r.i32();
  c.height = r.i32();
  if (c.width < 1 || c.height < 1 || c.width > kMaxImageSide || c.height > kMaxImageSide)
    r.fail(fmt::format("camera size {}x{} out of range", c.width, c.height));
  c.fx = r.finite64("fx");
  c.fy = r.finite64("fy");
  c.cx = r.finite64("cx");
  c.cy = r.finite64("cy");
  c.k1 = r.finite64("k1");
  c.k2 = r.finite64("k2");
  c.p1 = r.finite64("p1");
  c.p2 = r.finite64("p2");
  c.k3 = r.finite64("k3");
  if (c.fx <= 0 || c.fy <= 0) r.fail("focal lengths must be positive");
  info.pyramid_levels = r.i32();
  info.pyramid_scale_factor = r.finite64("pyramid scale factor");
  if (info.pyramid_levels < 1 || info.pyramid_levels > kMaxPyramidLevels)
    r.fail(fmt::format("pyramid levels {} out of range", info.pyramid_levels));
  if (info.pyramid_scale_factor <= 1.0 || info.pyramid_scale_factor > 4.0)
    r.fail(fmt::format("pyramid scale factor {} out of range", info.pyramid_scale_factor));
  info.vocabulary_name = r.str(4096);
  info.vocabulary_words = r.u64();
  info.vocabulary_checksum = r.u64();
  r.expect_end();
  return info;
}

Keyframe read_keyframe(ByteReader& r, const MapFileInfo& info) {
  Keyframe kf;
  kf.id = r.id<KeyframeId>();
  kf.frame_index = r.u64();
  kf.stamp = r.finite64("stamp");
  kf.map_id = MapId{r.u32()};
  kf.T_cw = read_pose(r);
  const std::uint32_t n = r.u32();
  constexpr std::size_t kFeatureBytes = 5 * 4 + 4 + 2 * 4 + kDescBytes + 8;
  r.need_records(n, kFeatureBytes);
  auto& f = kf.features;
  f.keypoints.resize(n);
  f.depth.resize(n);
  f.u_right.resize(n);
  f.descriptors = cv::Mat(static_cast<int>(n), kDescBytes, CV_8U);
  kf.points.resize(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    cv::KeyPoint& kp = f.keypoints[i];
    kp.pt.x = r.finite32("keypoint x");
    kp.pt.y = r.finite32("keypoint y");
    kp.size = r.finite32("keypoint size");
    kp.angle = r.finite32("keypoint angle");
    kp.response = r.finite32("keypoint response");
    kp.octave = r.i32();
    if (kp.octave < 0 || kp.octave >= info.pyramid_levels)
      r.fail(fmt::format("keyframe {} feature {}: octave {} outside the pyramid", kf.id, i, kp.octave));
    f.depth[i] = r.finite32("feature depth");
    f.u_right[i] = r.finite32("feature right coordinate");
    std::memcpy(f.descriptors.ptr<std::uint8_t>(static_cast<int>(i)), r.bytes(kDescBytes), kDescBytes);
    kf.points[i] = r.id<PointId>();
  }
  const std::uint32_t n_cov = r.u32();
  r.need_records(n_cov, 12);
  for (std::uint32_t i = 0; i < n_cov; ++i) {
    const KeyframeId other = r.id<KeyframeId>();
    const int w = r.i32();
    if (w < 0) r.fail(fmt::format("keyframe {}: negative covisibility weight", kf.id));
    if (!kf.covisibility.emplace(other, w).second)
      r.fail(fmt::format("keyframe {}: covisibility edge to {} listed twice", kf.id, other));
  }
  kf.parent = r.id<KeyframeId>();
  const std::uint32_t n_loop = r.u32();
  r.need_records(n_loop, 8);
  for (std::uint32_t i = 0; i < n_loop; ++i) kf.loop_edges.insert(r.id<KeyframeId>());
  const std::uint32_t jpeg_len = r.u32();
  if (jpeg_len > 0) {
    const std::uint8_t* p = r.bytes(jpeg_len);
    const std::span<const std::uint8_t> jpeg(p, jpeg_len);
    const auto size = jpeg_size(jpeg);
    if (!size || size->width < 1 || size->height < 1 || size->width > kMaxThumbnailSide ||
        size->height > kMaxThumbnailSide)
      r.fail(fmt::format("keyframe {}: thumbnail is not a JPEG of a sensible size", kf.id));
    const cv::Mat raw(1, static_cast<int>(jpeg_len), CV_8U, const_cast<std::uint8_t*>(p));
    kf.thumbnail = cv::imdecode(raw, cv::IMREAD_COLOR);
    if (kf.thumbnail.empty()) r.fail(fmt::format("keyframe {}: thumbnail JPEG does not decode", kf.id));
  }
  kf.index = make_feature_grid(f.keypoints, info.camera.width, info.camera.height);
  return kf;
}

MapPoint read_point(ByteReader& r) {
  MapPoint p;
  p.id = r.id<PointId>();
  p.position = r.vec3("point position");
  p.descriptor = cv::Mat(1, kDescBytes, CV_8U);
  std::memcpy(p.descriptor.ptr<std::uint8_t>(0), r.bytes(kDescBytes), kDescBytes);
  p.normal = r.vec3("point normal");
  p.min_distance = r.finite64("point min distance");
  p.max_distance = r.finite64("point max distance");
  if (p.min_distance < 0 || p.max_distance < p.min_distance)
    r.fail(fmt::format("point {}: distance range [{}, {}] is invalid", p.id, p.min_distance, p.max_distance));
  p.reference = r.id<KeyframeId>();
  p.first_keyframe = r.id<KeyframeId>();
  p.visible = r.i32();
  p.found = r.i32();
  if (p.visible < 0 || p.found < 0) r.fail(fmt::format("point {}: negative visible/found counters", p.id));
  const std::uint32_t n_obs = r.u32();
  r.need_records(n_obs, 12);
  for (std::uint32_t i = 0; i < n_obs; ++i) {
    const KeyframeId kid = r.id<KeyframeId>();
    const std::uint32_t feature = r.u32();
    if (feature > static_cast<std::uint32_t>(std::numeric_limits<int>::max()))
      r.fail(fmt::format("point {}: feature index {} out of range", p.id, feature));
    if (!p.observations.emplace(kid, static_cast<int>(feature)).second)
      r.fail(fmt::format("point {}: observed twice in keyframe {}", p.id, kid));
  }
  return p;
}

// Cross-references: every id named must be a record of the file, and the two directions of an
// observation (keyframe feature -> point, point -> keyframe feature) must agree.
void validate_references(MapContents& m, const std::string& file) {
  auto fail = [&](const std::string& what) { throw InputError(file, 0, what); };
  std::unordered_map<KeyframeId, std::size_t> kf_at;
  std::unordered_map<PointId, std::size_t> pt_at;
  for (std::size_t i = 0; i < m.keyframes.size(); ++i) {
    const KeyframeId id = m.keyframes[i].id;
    if (id == kNoKeyframe || id >= m.next_keyframe_id)
      fail(fmt::format("keyframe id {} is 0 or not below the id counter {}", id, m.next_keyframe_id));
    if (!kf_at.emplace(id, i).second) fail(fmt::format("keyframe id {} appears twice", id));
  }
  for (std::size_t i = 0; i < m.points.size(); ++i) {
    const PointId id = m.points[i].id;
    if (id == kNoPoint || id >= m.next_point_id)
      fail(fmt::format("point id {} is 0 or not below the id counter {}", id, m.next_point_id));
    if (!pt_at.emplace(id, i).second) fail(fmt::format("point id {} appears twice", id));
  }
  for (Keyframe& kf : m.keyframes) {
    for (std::size_t i = 0; i < kf.points.size(); ++i) {
      const PointId pid = kf.points[i];
      if (pid == kNoPoint) continue;
      const auto it = pt_at.find(pid);
      if (it == pt_at.end())
        fail(fmt::format("keyframe {} feature {} references missing point {}", kf.id, i, pid));
      const auto& obs = m.points[it->second].observations;
      const auto o = obs.find(kf.id);
      if (o == obs.end() || o->second != static_cast<int>(i))
        fail(fmt::format("keyframe {} feature {} names point {}, which does not list that observation", kf.id,
                         i, pid));
    }
    for (const auto& [other, w] : kf.covisibility) {
      if (other == kf.id || !kf_at.contains(other))
        fail(fmt::format("keyframe {} has a covisibility edge to missing keyframe {}", kf.id, other));
    }
    for (KeyframeId other : kf.loop_edges) {
      if (other == kf.id || !kf_at.contains(other))
        fail(fmt::format("keyframe {} has a loop edge to missing keyframe {}", kf.id, other));
    }
    if (kf.parent != kNoKeyframe) {
      if (!kf_at.contains(kf.parent))
        fail(fmt::format("keyframe {} has missing spanning-tree parent {}", kf.id, kf.parent));
      // Parents are always older keyframes (map.cpp keeps this), which also rules out cycles.
      if (kf.parent >= kf.id)
        fail(fmt::format("keyframe {} has parent {} that is not older", kf.id, kf.parent));
      // Maps not merged yet share no edge: each has its own spanning tree.
      if (const Keyframe& parent = m.keyframes[kf_at.at(kf.parent)]; parent.map_id != kf.map_id)
        fail(fmt::format("keyframe {} (map {}) has spanning-tree parent {} in map {}", kf.id,
                         to_int(kf.map_id), kf.parent, to_int(parent.map_id)));
    }
  }
  for (Keyframe& kf : m.keyframes) {
    if (kf.parent != kNoKeyframe) m.keyframes[kf_at.at(kf.parent)].children.insert(kf.id);
  }
  for (const MapPoint& p : m.points) {
    if (p.observations.empty()) fail(fmt::format("point {} has no observations", p.id));
    for (const auto& [kid, feature] : p.observations) {
      const auto it = kf_at.find(kid);
      if (it == kf_at.end()) fail(fmt::format("point {} is observed by missing keyframe {}", p.id, kid));
      const Keyframe& kf = m.keyframes[it->second];
      if (static_cast<std::size_t>(feature) >= kf.points.size() ||
          kf.points[static_cast<std::size_t>(feature)] != p.id)
        fail(fmt::format("point {} lists feature {} of keyframe {}, which does not name it", p.id, feature,
                         kid));
    }
    if (!p.observations.contains(p.reference))
      fail(fmt::format("point {} has reference keyframe {} that does not observe it", p.id, p.reference));
    if (p.first_keyframe >= m.next_keyframe_id)
      fail(fmt::format("point {} was created by keyframe {}, beyond the id counter", p.id, p.first_keyframe));
  }
}

}  // namespace

bool MapFileInfo::operator==(const MapFileInfo& o) const {
  const auto& a = camera;
  const auto& b = o.camera;
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy && a.cx == b.cx &&
         a.cy == b.cy && a.k1 == b.k1 && a.k2 == b.k2 && a.p1 == b.p1 && a.p2 == b.p2 && a.k3 == b.k3 &&
         pyramid_levels == o.pyramid_levels && pyramid_scale_factor == o.pyramid_scale_factor &&
         vocabulary_name == o.vocabulary_name && vocabulary_words == o.vocabulary_words &&
         vocabulary_checksum == o.vocabulary_checksum;
}

std::uint64_t vocabulary_fingerprint(const std::filesystem::path& vocabulary_file) {
  std::ifstream in(vocabulary_file, std::ios::binary | std::ios::ate);
  if (!in) throw InputError(vocabulary_file.string(), 0, "cannot open the vocabulary");
  const auto size = static_cast<std::streamoff>(in.tellg());
  if (size < 8) throw InputError(vocabulary_file.string(), 0, "vocabulary file too short for a checksum");
  in.seekg(size - 8);
  std::array<std::uint8_t, 8> b{};
  in.read(reinterpret_cast<char*>(b.data()), 8);
  if (!in) throw InputError(vocabulary_file.string(), 0, "cannot read the vocabulary checksum");
  return load_le<std::uint64_t>(b.data());
}

MapContents snapshot_map(Map& map, const MapFileInfo& info) {
  MapContents m;
  m.info = info;
  MapView view = map.view();
  // Live records only; references into culled records are redirected or dropped so that the file
  // is closed under its own ids.
  std::unordered_set<KeyframeId> live_kf;
  for (const auto& [id, kf] : view.keyframes()) {
    if (!kf.bad) live_kf.insert(id);
  }
  std::unordered_set<PointId> live_pt;
  for (const auto& [id, p] : view.points()) {
    if (p.bad) continue;
    const bool observed = std::any_of(p.observations.begin(), p.observations.end(),
                                      [&](const auto& o) { return live_kf.contains(o.first); });
    if (observed) live_pt.insert(id);
  }
  KeyframeId max_kf;
  PointId max_pt;
  for (KeyframeId id : view.keyframe_ids_sorted()) {
    const Keyframe& src = *view.keyframe(id);
    Keyframe kf;
    kf.id = id;
    kf.frame_index = src.frame_index;
    kf.stamp = src.stamp;
    kf.map_id = src.map_id;
    kf.T_cw = src.T_cw;
    kf.features = src.features;
    kf.thumbnail = src.thumbnail;
    kf.points = src.points;
    for (PointId& pid : kf.points) {
      if (pid != kNoPoint && !live_pt.contains(pid)) pid = kNoPoint;
    }
    for (const auto& [other, w] : src.covisibility) {
      if (live_kf.contains(other) && other != id) kf.covisibility.emplace(other, w);
    }
    for (KeyframeId other : src.loop_edges) {
      if (live_kf.contains(other) && other != id) kf.loop_edges.insert(other);
    }
    // A culled parent hands its children on in erase_keyframe; follow the chain in case it did not.
    KeyframeId parent = src.parent;
    for (int hops = 0; parent != kNoKeyframe && !live_kf.contains(parent) && hops < 1000; ++hops) {
      const Keyframe* pk = view.keyframe(parent);
      parent = pk == nullptr ? kNoKeyframe : pk->parent;
    }
    kf.parent = live_kf.contains(parent) && parent < id ? parent : kNoKeyframe;
    max_kf = std::max(max_kf, id);
    m.keyframes.push_back(std::move(kf));
  }
  std::vector<PointId> point_ids(live_pt.begin(), live_pt.end());
  std::sort(point_ids.begin(), point_ids.end());
  std::unordered_map<KeyframeId, const Keyframe*> saved_kf;
  for (const Keyframe& kf : m.keyframes) saved_kf.emplace(kf.id, &kf);
  for (PointId id : point_ids) {
    const MapPoint& src = *view.point(id);
    MapPoint p = src;
    p.observations.clear();
    for (const auto& [kid, feature] : src.observations) {
      const auto it = saved_kf.find(kid);
      if (it == saved_kf.end()) continue;
      const auto& pts = it->second->points;
      // Keep an observation only when both directions agree.
      if (static_cast<std::size_t>(feature) < pts.size() && pts[static_cast<std::size_t>(feature)] == id)
        p.observations.emplace(kid, feature);
    }
    if (p.observations.empty()) continue;
    if (!p.observations.contains(p.reference)) p.reference = p.observations.begin()->first;
    p.replaced_by = kNoPoint;
    max_pt = std::max(max_pt, id);
    m.points.push_back(std::move(p));
  }
  // Keyframe slots must be confirmed by a saved point that lists this very feature.
  std::unordered_map<PointId, const MapPoint*> saved_pt;
  for (const MapPoint& p : m.points) saved_pt.emplace(p.id, &p);
  for (Keyframe& kf : m.keyframes) {
    for (std::size_t i = 0; i < kf.points.size(); ++i) {
      PointId& pid = kf.points[i];
      if (pid == kNoPoint) continue;
      const auto it = saved_pt.find(pid);
      if (it == saved_pt.end()) {
        pid = kNoPoint;
        continue;
      }
      const auto o = it->second->observations.find(kf.id);
      if (o == it->second->observations.end() || o->second != static_cast<int>(i)) pid = kNoPoint;
    }
  }
  // The map's own counters, so ids are never reused after the loaded map grows again.
  const auto [next_kf, next_pt] = view.next_ids();
  m.next_keyframe_id = std::max(next_kf, max_kf.next());
  m.next_point_id = std::max(next_pt, max_pt.next());
  return m;
}

std::vector<std::uint8_t> serialize_map(const MapContents& m) {
  std::vector<std::uint8_t> out(kMagic.begin(), kMagic.end());
  {
    ByteWriter w;
    w.u32(kMapFormatVersion);
    out.insert(out.end(), w.buffer().begin(), w.buffer().end());
  }
  {
    ByteWriter w;
    w.u64(m.keyframes.size());
    w.u64(m.points.size());
    w.id(m.next_keyframe_id);
    w.id(m.next_point_id);
    const auto& c = m.info.camera;
    w.i32(c.width);
    w.i32(c.height);
    for (double v : {c.fx, c.fy, c.cx, c.cy, c.k1, c.k2, c.p1, c.p2, c.k3}) w.f64(v);
    w.i32(m.info.pyramid_levels);
    w.f64(m.info.pyramid_scale_factor);
    w.str(m.info.vocabulary_name);
    w.u64(m.info.vocabulary_words);
    w.u64(m.info.vocabulary_checksum);
    append_section(out, kTagHead, w.buffer());
  }
  {
    ByteWriter w;
    w.u32(static_cast<std::uint32_t>(m.keyframes.size()));
    for (const Keyframe& kf : m.keyframes) {
      w.id(kf.id);
      w.u64(kf.frame_index);
      w.f64(kf.stamp);
      w.u32(to_int(kf.map_id));
      write_pose(w, kf.T_cw);
      const auto& f = kf.features;
      w.u32(static_cast<std::uint32_t>(f.size()));
      for (std::size_t i = 0; i < f.size(); ++i) {
        const cv::KeyPoint& kp = f.keypoints[i];
        w.f32(kp.pt.x);
        w.f32(kp.pt.y);
        w.f32(kp.size);
        w.f32(kp.angle);
        w.f32(kp.response);
        w.i32(kp.octave);
        w.f32(i < f.depth.size() ? f.depth[i] : -1.f);
        w.f32(i < f.u_right.size() ? f.u_right[i] : -1.f);
        write_descriptor(w, f.descriptors, static_cast<int>(i));
        w.id(i < kf.points.size() ? kf.points[i] : kNoPoint);
      }
      w.u32(static_cast<std::uint32_t>(kf.covisibility.size()));
      for (const auto& [other, weight] : kf.covisibility) {
        w.id(other);
        w.i32(weight);
      }
      w.id(kf.parent);
      w.u32(static_cast<std::uint32_t>(kf.loop_edges.size()));
      for (KeyframeId other : kf.loop_edges) w.id(other);
      const auto jpeg = encode_thumbnail(kf.thumbnail);
      w.u32(static_cast<std::uint32_t>(jpeg.size()));
      w.bytes(jpeg.data(), jpeg.size());
    }
    append_section(out, kTagKeyframes, w.buffer());
  }
  {
    ByteWriter w;
    w.u32(static_cast<std::uint32_t>(m.points.size()));
    for (const MapPoint& p : m.points) {
      w.id(p.id);
      w.vec3(p.position);
      write_descriptor(w, p.descriptor, 0);
      w.vec3(p.normal);
      w.f64(p.min_distance);
      w.f64(p.max_distance);
      w.id(p.reference);
      w.id(p.first_keyframe);
      w.i32(p.visible);
      w.i32(p.found);
      w.u32(static_cast<std::uint32_t>(p.observations.size()));
      for (const auto& [kid, feature] : p.observations) {
        w.id(kid);
        w.u32(static_cast<std::uint32_t>(feature));
      }
    }
    append_section(out, kTagPoints, w.buffer());
  }
  {
    // The END section: total file size and the CRC of everything before it.
    ByteWriter w;
    w.u64(out.size() + kFrameBytes + 12);
    w.u32(crc32(out));
    append_section(out, kTagEnd, w.buffer());
  }
  return out;
}

MapSaveResult save_map(Map& map, const std::filesystem::path& file, const MapFileInfo& info) {
  const MapContents m = snapshot_map(map, info);
  const std::vector<std::uint8_t> bytes = serialize_map(m);
  const std::filesystem::path tmp = file.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw Error("cannot write map file " + tmp.string());
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    out.close();
    if (!out) throw Error("error writing map file " + tmp.string());
  }
  std::error_code ec;
  std::filesystem::rename(tmp, file, ec);
  if (ec) throw Error("cannot rename " + tmp.string() + " to " + file.string() + ": " + ec.message());
  return {m.keyframes.size(), m.points.size(), bytes.size()};
}

MapContents parse_map(std::span<const std::uint8_t> bytes, const std::string& name) {
  auto fail = [&](const std::string& what) { throw InputError(name, 0, what); };
  if (bytes.size() < kMagic.size() || !std::equal(kMagic.begin(), kMagic.end(), bytes.begin()))
    fail("not a StillPoint map file (bad magic)");
  if (bytes.size() < kPreambleBytes)
    fail(fmt::format("truncated at byte offset {} in the file header (format version)", bytes.size()));
  ByteReader pre(bytes.subspan(8, 4), 8, name, "header");
  const std::uint32_t version = pre.u32();
  if (version != kMapFormatVersion)
    fail(fmt::format(
        "map file format version {}, this build reads version {} (re-create the map with this build)",
        version, kMapFormatVersion));

  MapContents m;
  std::uint64_t n_keyframes = 0, n_points = 0;
  const std::array<std::uint32_t, 4> order = {kTagHead, kTagKeyframes, kTagPoints, kTagEnd};
  std::size_t pos = kPreambleBytes;
  for (std::uint32_t expected : order) {
    const std::string section = tag_name(expected);
    if (bytes.size() - pos < 12)
      fail(fmt::format("truncated at byte offset {} in section {} (section header)", bytes.size(), section));
    ByteReader frame(bytes.subspan(pos, 12), pos, name, section);
    const std::uint32_t tag = frame.u32();
    const std::uint64_t length = frame.u64();
    if (tag != expected)
      fail(fmt::format("at byte offset {}: expected section {}, found '{}'", pos, section, tag_name(tag)));
    const std::size_t left = bytes.size() - pos - 12;
    if (length > left || left - length < 4)
      fail(
          fmt::format("truncated at byte offset {} in section {} (it declares {} payload bytes, {} are left)",
                      bytes.size(), section, length, left >= 4 ? left - 4 : 0));
    const auto body = bytes.subspan(pos, 12 + length);
    ByteReader crc_reader(bytes.subspan(pos + 12 + length, 4), pos + 12 + length, name, section);
    const std::uint32_t stored = crc_reader.u32();
    const std::uint32_t computed = crc32(body);
    if (stored != computed)
      fail(
          fmt::format("checksum mismatch in section {} (stored {:08x}, computed {:08x}): the file is corrupt",
                      section, stored, computed));
    ByteReader r(bytes.subspan(pos + 12, length), pos + 12, name, section);
    if (expected == kTagHead) {
      m.info = read_head(r, n_keyframes, n_points, m.next_keyframe_id, m.next_point_id);
    } else if (expected == kTagKeyframes) {
      const std::uint32_t n = r.u32();
      if (n != n_keyframes) r.fail(fmt::format("{} keyframes, the header says {}", n, n_keyframes));
      r.need_records(n, kMinKeyframeBytes);
      m.keyframes.reserve(n);
      for (std::uint32_t i = 0; i < n; ++i) m.keyframes.push_back(read_keyframe(r, m.info));
      r.expect_end();
    } else if (expected == kTagPoints) {
      const std::uint32_t n = r.u32();
      if (n != n_points) r.fail(fmt::format("{} map points, the header says {}", n, n_points));
      r.need_records(n, kMinPointBytes);
      m.points.reserve(n);
      for (std::uint32_t i = 0; i < n; ++i) m.points.push_back(read_point(r));
      r.expect_end();
    } else {
      const std::uint64_t size = r.u64();
      const std::uint32_t overall = r.u32();
      r.expect_end();
      if (size != pos + 12 + length + 4)
        fail(fmt::format("section END records a file size of {} bytes, it ends at {}", size,
                         pos + 12 + length + 4));
      if (overall != crc32(bytes.subspan(0, pos)))
        fail("checksum mismatch over the whole file (section END): the file is corrupt");
    }
    pos += 12 + length + 4;
  }
  if (pos != bytes.size())
    fail(fmt::format("{} unexpected bytes after the end of the map", bytes.size() - pos));
  validate_references(m, name);
  return m;
}

MapContents read_map_file(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary | std::ios::ate);
  if (!in) throw InputError(file.string(), 0, "cannot open the map file");
  const auto size = static_cast<std::streamoff>(in.tellg());
  if (size < 0) throw InputError(file.string(), 0, "cannot read the map file");
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(size));
  in.seekg(0);
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (!in) throw InputError(file.string(), 0, "cannot read the map file");
  return parse_map(bytes, file.string());
}

MapFileInfo load_map(const std::filesystem::path& file, Map& map) {
  MapContents m = read_map_file(file);
  MapView view = map.view();
  view.restore(std::move(m.keyframes), std::move(m.points), m.next_keyframe_id, m.next_point_id);
  return m.info;
}

void reseal_map_bytes(std::vector<std::uint8_t>& bytes) {
  std::size_t pos = kPreambleBytes;
  while (bytes.size() >= pos + 12) {
    const auto length = load_le<std::uint64_t>(bytes.data() + pos + 4);
    if (length > bytes.size() - pos - 12 || bytes.size() - pos - 12 - length < 4) return;
    const bool end = bytes[pos] == 'E' && bytes[pos + 1] == 'N' && bytes[pos + 2] == 'D' && length == 12;
    if (end) {
      store_le<std::uint64_t>(bytes.data() + pos + 12, pos + 12 + length + 4);
      store_le<std::uint32_t>(bytes.data() + pos + 20,
                              crc32(std::span<const std::uint8_t>(bytes.data(), pos)));
    }
    store_le<std::uint32_t>(bytes.data() + pos + 12 + length,
                            crc32(std::span<const std::uint8_t>(bytes.data() + pos, 12 + length)));
    pos += 12 + length + 4;
  }
}

}  // namespace sp::map
