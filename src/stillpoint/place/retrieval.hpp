#pragma once
// Place-recognition data sets and the evaluation protocol (L2 distance, top-20 retrieval,
// Recall@1/5/10/20 over all queries). No libtorch here.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <filesystem>
#include <string>
#include <vector>

namespace sp::place {

// One image of a dynsynth `places` folder.
struct PlaceImage {
  std::filesystem::path file;                             // absolute image path
  std::string room;                                       // scene.txt of its folder
  int index = 0;                                          // line order in poses.txt (0-based)
  Eigen::Vector3d t = Eigen::Vector3d::Zero();            // camera centre in the world (m)
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();  // T_world_camera rotation
};

// Rules of the places data (documented in docs/place_recognition.md).
struct PlaceRules {
  double positive_distance = 0.5;  // m, same room
  double positive_angle_deg = 30;  // degrees of relative rotation
  double negative_distance = 3.0;  // m, or another room
  // Same-room negatives also need this much relative rotation (0: distance alone). A view farther
  // back along the same line sees the same wall: without it, hard mining picks such false negatives.
  double negative_min_angle_deg = 0;
};

// Reads poses.txt ("rgb/NNNNNN.jpg tx ty tz qx qy qz qw") and scene.txt; InputError names file and line.
std::vector<PlaceImage> load_places_folder(const std::filesystem::path& dir);
// `dir` itself when it holds poses.txt, otherwise every immediate subfolder that does (sorted).
std::vector<std::filesystem::path> find_places_folders(const std::filesystem::path& dir);

[[nodiscard]] double rotation_angle_deg(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b);
[[nodiscard]] bool is_positive(const PlaceImage& a, const PlaceImage& b, const PlaceRules& rules);
[[nodiscard]] bool is_negative(const PlaceImage& a, const PlaceImage& b, const PlaceRules& rules);

// Query and database images with the references that count as correct for each query.
struct RetrievalSet {
  std::string name;  // nordland | corridor | places
  std::string rule;  // how the split and ground truth were made
  std::vector<std::filesystem::path> queries;
  std::vector<std::filesystem::path> database;
  std::vector<std::vector<int>> ground_truth;  // per query, sorted database indices
  int dropped_queries = 0;                     // places: queries without any true match
};

// Detects the layout: nordland (summer/ + winter/), corridor (query/ + ref/ + ground_truth.txt), or
// dynsynth places (a folder with poses.txt, or a folder of such folders).
RetrievalSet load_retrieval_set(const std::filesystem::path& dir, const PlaceRules& rules = {});

// Pairwise squared L2 distances between the rows of q (Q×D) and db (N×D).
Eigen::MatrixXf squared_distances(const Eigen::MatrixXf& q, const Eigen::MatrixXf& db);

// Indices of the n smallest entries of each row (ascending distance, ties by index).
std::vector<std::vector<int>> top_n(const Eigen::MatrixXf& distances, int n);

struct RecallResult {
  static constexpr std::array<int, 4> kN{1, 5, 10, 20};
  std::array<double, 4> recall{};  // fraction of queries with a correct match in the top N
  int queries = 0;
};

// Recall@1/5/10/20 given a Q×N distance matrix (smaller = more similar) and the ground truth.
RecallResult recall_at_n(const Eigen::MatrixXf& distances, const std::vector<std::vector<int>>& ground_truth);

}  // namespace sp::place
