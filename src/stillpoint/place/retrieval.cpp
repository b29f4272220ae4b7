#include "stillpoint/place/retrieval.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numeric>
#include <sstream>

#include "stillpoint/common/error.hpp"

namespace sp::place {

namespace fs = std::filesystem;

std::vector<PlaceImage> load_places_folder(const fs::path& dir) {
  const fs::path poses = dir / "poses.txt";
  std::ifstream in(poses);
  if (!in) throw sp::InputError(poses.string(), 0, "cannot open (not a dynsynth places folder?)");
  std::string room = dir.filename().string();
  if (std::ifstream sc(dir / "scene.txt"); sc) {
    std::string s;
    if (std::getline(sc, s) && !s.empty()) room = s;
  }
  std::vector<PlaceImage> out;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    std::string rel;
    double v[7];
    if (!(ss >> rel >> v[0] >> v[1] >> v[2] >> v[3] >> v[4] >> v[5] >> v[6])) {
      throw sp::InputError(poses.string(), lineno, "expected 'rgb/NNNNNN.jpg tx ty tz qx qy qz qw'");
    }
    PlaceImage im;
    im.file = fs::absolute(dir / rel);
    im.room = room;
    im.index = static_cast<int>(out.size());
    im.t = Eigen::Vector3d(v[0], v[1], v[2]);
    im.q = Eigen::Quaterniond(v[6], v[3], v[4], v[5]);
    if (std::abs(im.q.norm() - 1.0) > 1e-3)
      throw sp::InputError(poses.string(), lineno, "quaternion not unit");
    im.q.normalize();
    out.push_back(std::move(im));
  }
  if (out.empty()) throw sp::InputError(poses.string(), 0, "no images");
  return out;
}

std::vector<fs::path> find_places_folders(const fs::path& dir) {
  if (fs::exists(dir / "poses.txt")) return {dir};
  std::vector<fs::path> out;
  if (fs::is_directory(dir)) {
    for (const auto& e : fs::directory_iterator(dir)) {
      if (e.is_directory() && fs::exists(e.path() / "poses.txt")) out.push_back(e.path());
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

double rotation_angle_deg(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return Eigen::AngleAxisd(a.inverse() * b).angle() * 180.0 / M_PI;
}

bool is_positive(const PlaceImage& a, const PlaceImage& b, const PlaceRules& r) {
  return a.room == b.room && (a.t - b.t).norm() <= r.positive_distance &&
         rotation_angle_deg(a.q, b.q) <= r.positive_angle_deg;
}

bool is_negative(const PlaceImage& a, const PlaceImage& b, const PlaceRules& r) {
  if (a.room != b.room) return true;
  if ((a.t - b.t).norm() <= r.negative_distance) return false;
  return r.negative_min_angle_deg <= 0 || rotation_angle_deg(a.q, b.q) > r.negative_min_angle_deg;
}

namespace {

std::vector<fs::path> sorted_images(const fs::path& dir) {
  std::vector<fs::path> out;
  for (const auto& e : fs::directory_iterator(dir)) {
    const auto ext = e.path().extension().string();
    if (e.is_regular_file() && (ext == ".png" || ext == ".jpg" || ext == ".jpeg")) out.push_back(e.path());
  }
  std::sort(out.begin(), out.end());
  return out;
}

RetrievalSet load_nordland(const fs::path& dir) {
  RetrievalSet set;
  set.name = "nordland";
  set.rule = "queries winter, database summer, correct if |index difference| <= 2";
  set.queries = sorted_images(dir / "winter");
  set.database = sorted_images(dir / "summer");
  if (set.queries.size() != set.database.size() || set.queries.empty()) {
    throw sp::InputError(dir.string(), 0,
                         "nordland: summer/ and winter/ must hold the same number of images");
  }
  const int n = static_cast<int>(set.database.size());
  for (int i = 0; i < n; ++i) {
    std::vector<int> gt;
    for (int j = std::max(0, i - 2); j <= std::min(n - 1, i + 2); ++j) gt.push_back(j);
    set.ground_truth.push_back(std::move(gt));
  }
  return set;
}

RetrievalSet load_corridor(const fs::path& dir) {
  RetrievalSet set;
  set.name = "corridor";
  set.rule = "query/ vs ref/, correct references from ground_truth.txt";
  set.queries = sorted_images(dir / "query");
  set.database = sorted_images(dir / "ref");
  set.ground_truth.assign(set.queries.size(), {});
  const fs::path gt_file = dir / "ground_truth.txt";
  std::ifstream in(gt_file);
  if (!in) throw sp::InputError(gt_file.string(), 0, "cannot open");
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#') continue;
    const auto colon = line.find(':');
    if (colon == std::string::npos) throw sp::InputError(gt_file.string(), lineno, "expected 'q: r1 r2 ...'");
    int q = -1;
    try {
      q = std::stoi(line.substr(0, colon));
    } catch (const std::exception&) {
      throw sp::InputError(gt_file.string(), lineno, "bad query index");
    }
    if (q < 0 || q >= static_cast<int>(set.queries.size())) {
      throw sp::InputError(gt_file.string(), lineno, "query index out of range");
    }
    std::istringstream ss(line.substr(colon + 1));
    int r;
    while (ss >> r) {
      if (r < 0 || r >= static_cast<int>(set.database.size())) {
        throw sp::InputError(gt_file.string(), lineno, "reference index out of range");
      }
      set.ground_truth[q].push_back(r);
    }
    std::sort(set.ground_truth[q].begin(), set.ground_truth[q].end());
  }
  return set;
}

RetrievalSet load_places(const fs::path& dir, const PlaceRules& rules) {
  RetrievalSet set;
  set.name = "places";
  set.rule =
      "per room: odd poses.txt lines are queries, even lines the database (all rooms pooled); "
      "correct = same room, <= " +
      std::to_string(rules.positive_distance).substr(0, 4) +
      " m and <= " + std::to_string(rules.positive_angle_deg).substr(0, 4) +
      " deg; queries without a correct reference are dropped";
  std::vector<PlaceImage> q_imgs, db_imgs;
  for (const auto& folder : find_places_folders(dir)) {
    for (auto& im : load_places_folder(folder)) (im.index % 2 == 1 ? q_imgs : db_imgs).push_back(im);
  }
  if (q_imgs.empty() || db_imgs.empty()) throw sp::InputError(dir.string(), 0, "no places folders found");
  for (const auto& d : db_imgs) set.database.push_back(d.file);
  for (const auto& q : q_imgs) {
    std::vector<int> gt;
    for (int j = 0; j < static_cast<int>(db_imgs.size()); ++j) {
      if (is_positive(q, db_imgs[j], rules)) gt.push_back(j);
    }
    if (gt.empty()) {
      ++set.dropped_queries;
      continue;
    }
    set.queries.push_back(q.file);
    set.ground_truth.push_back(std::move(gt));
  }
  return set;
}

}  // namespace

RetrievalSet load_retrieval_set(const fs::path& dir, const PlaceRules& rules) {
  if (!fs::is_directory(dir)) throw sp::InputError(dir.string(), 0, "data set folder not found");
  if (fs::is_directory(dir / "summer") && fs::is_directory(dir / "winter")) return load_nordland(dir);
  if (fs::is_directory(dir / "query") && fs::is_directory(dir / "ref")) return load_corridor(dir);
  return load_places(dir, rules);
}

Eigen::MatrixXf squared_distances(const Eigen::MatrixXf& q, const Eigen::MatrixXf& db) {
  Eigen::MatrixXf d = -2.0f * (q * db.transpose());
  d.colwise() += q.rowwise().squaredNorm();
  d.rowwise() += db.rowwise().squaredNorm().transpose();
  return d.cwiseMax(0.0f);
}

std::vector<std::vector<int>> top_n(const Eigen::MatrixXf& distances, int n) {
  std::vector<std::vector<int>> out(static_cast<size_t>(distances.rows()));
  const int cols = static_cast<int>(distances.cols());
  const int k = std::min(n, cols);
  std::vector<int> idx(static_cast<size_t>(cols));
  for (Eigen::Index r = 0; r < distances.rows(); ++r) {
    std::iota(idx.begin(), idx.end(), 0);
    std::partial_sort(idx.begin(), idx.begin() + k, idx.end(), [&](int a, int b) {
      const float da = distances(r, a), db = distances(r, b);
      return da < db || (da == db && a < b);
    });
    out[static_cast<size_t>(r)].assign(idx.begin(), idx.begin() + k);
  }
  return out;
}

RecallResult recall_at_n(const Eigen::MatrixXf& distances,
                         const std::vector<std::vector<int>>& ground_truth) {
  if (static_cast<size_t>(distances.rows()) != ground_truth.size()) {
    throw sp::Error("recall_at_n: one ground-truth list per query is needed");
  }
  RecallResult res;
  res.queries = static_cast<int>(ground_truth.size());
  if (res.queries == 0) return res;
  const auto top = top_n(distances, RecallResult::kN.back());
  std::array<int, 4> hits{};
  for (size_t q = 0; q < top.size(); ++q) {
    // Rank of the first correct retrieval (or past the list).
    int first = static_cast<int>(top[q].size());
    for (int r = 0; r < static_cast<int>(top[q].size()); ++r) {
      if (std::find(ground_truth[q].begin(), ground_truth[q].end(), top[q][r]) != ground_truth[q].end()) {
        first = r;
        break;
      }
    }
    for (size_t i = 0; i < 4; ++i) hits[i] += first < RecallResult::kN[i] ? 1 : 0;
  }
  for (size_t i = 0; i < 4; ++i) res.recall[i] = static_cast<double>(hits[i]) / res.queries;
  return res;
}

}  // namespace sp::place
