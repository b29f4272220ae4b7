#include "stillpoint/dynamic/dynamic_filter.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include <unordered_map>

#include "stillpoint/common/error.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/dynamic/decoders.hpp"
#include "stillpoint/dynamic/depth_lookup.hpp"

namespace sp::dyn {

namespace {

float median_of(std::vector<float> v) {
  if (v.empty()) return 0.f;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

float quantile_of(std::vector<float> v, double q) {
  if (v.empty()) return 0.f;
  const auto k = static_cast<std::ptrdiff_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[static_cast<std::size_t>(k)];
}

cv::Rect2f grow(const cv::Rect2f& r, float m) {
  return {r.x - m, r.y - m, r.width + 2 * m, r.height + 2 * m};
}

bool inside(const cv::Rect2f& r, const cv::Point2f& p) {
  return p.x >= r.x && p.y >= r.y && p.x < r.x + r.width && p.y < r.y + r.height;
}

// Indices of the strongest keypoint per cell of `roi` (cells of `cell` px), at most `max_points`.
std::vector<int> bucket(const std::vector<cv::KeyPoint>& kps, const cv::Rect2f& roi, int cell,
                        int max_points) {
  const int gw = std::max(1, static_cast<int>(std::ceil(roi.width / cell)));
  const int gh = std::max(1, static_cast<int>(std::ceil(roi.height / cell)));
  std::vector<int> best(static_cast<std::size_t>(gw * gh), -1);
  const auto resp = [&](int i) { return kps[static_cast<std::size_t>(i)].response; };
  for (int i = 0; i < static_cast<int>(kps.size()); ++i) {
    const cv::Point2f& p = kps[static_cast<std::size_t>(i)].pt;
    if (!roi.contains(p)) continue;
    const int gx = std::clamp(static_cast<int>((p.x - roi.x) / static_cast<float>(cell)), 0, gw - 1);
    const int gy = std::clamp(static_cast<int>((p.y - roi.y) / static_cast<float>(cell)), 0, gh - 1);
    int& b = best[static_cast<std::size_t>(gy * gw + gx)];
    if (b < 0 || resp(i) > resp(b)) b = i;
  }
  std::vector<int> chosen;
  for (int b : best) {
    if (b >= 0) chosen.push_back(b);
  }
  if (static_cast<int>(chosen.size()) > max_points) {
    std::nth_element(chosen.begin(), chosen.begin() + max_points, chosen.end(),
                     [&](int a, int b) { return resp(a) > resp(b); });
    chosen.resize(static_cast<std::size_t>(max_points));
  }
  return chosen;
}

// Points to track: keypoints spread over the image by a grid, plus a denser sample inside each
// candidate box so every box gets enough points to be judged; corners when there are no keypoints.
std::vector<cv::Point2f> pick_points(const cv::Mat& gray, const std::vector<cv::KeyPoint>* kps, int cell,
                                     int max_points, const std::vector<Detection>& boxes, int box_points) {
  std::vector<cv::Point2f> pts;
  const cv::Rect2f image(0.f, 0.f, static_cast<float>(gray.cols), static_cast<float>(gray.rows));
  if (kps != nullptr && static_cast<int>(kps->size()) >= 20) {
    std::vector<int> chosen = bucket(*kps, image, cell, max_points);
    std::vector<bool> taken(kps->size(), false);
    for (int i : chosen) taken[static_cast<std::size_t>(i)] = true;
    for (const Detection& d : boxes) {
      const cv::Rect2f roi = d.box & image;
      if (box_points <= 0 || roi.area() < 1.f) continue;
      const int c = std::max(4, static_cast<int>(std::sqrt(roi.area() / static_cast<float>(box_points))));
      for (int i : bucket(*kps, roi, c, box_points)) {
        if (!taken[static_cast<std::size_t>(i)])
          chosen.push_back(i), taken[static_cast<std::size_t>(i)] = true;
      }
    }
    for (int i : chosen) pts.push_back((*kps)[static_cast<std::size_t>(i)].pt);
  } else {
    cv::goodFeaturesToTrack(gray, pts, max_points, 0.01, cell / 2.0);
  }
  return pts;
}

// Buckets of point indices for radius queries.
class PointGrid {
 public:
  PointGrid(const std::vector<cv::Point2f>& pts, float cell) : pts_(pts), cell_(std::max(cell, 1.f)) {
    for (int i = 0; i < static_cast<int>(pts.size()); ++i)
      cells_[key(pts[static_cast<std::size_t>(i)])].push_back(i);
  }
  // Calls f(index, squared distance) for every point within r of p.
  template <typename F>
  void for_each_near(const cv::Point2f& p, float r, F&& f) const {
    const int span = static_cast<int>(std::ceil(r / cell_));
    const auto [cx, cy] = coords(p);
    for (int dy = -span; dy <= span; ++dy) {
      for (int dx = -span; dx <= span; ++dx) {
        const auto it = cells_.find(pack(cx + dx, cy + dy));
        if (it == cells_.end()) continue;
        for (int i : it->second) {
          const cv::Point2f d = pts_[static_cast<std::size_t>(i)] - p;
          const float d2 = d.dot(d);
          if (d2 <= r * r) f(i, d2);
        }
      }
    }
  }

 private:
  [[nodiscard]] std::pair<int, int> coords(const cv::Point2f& p) const {
    return {static_cast<int>(std::floor(p.x / cell_)), static_cast<int>(std::floor(p.y / cell_))};
  }
  static long long pack(int x, int y) { return (static_cast<long long>(x) << 32) ^ static_cast<unsigned>(y); }
  [[nodiscard]] long long key(const cv::Point2f& p) const {
    const auto [x, y] = coords(p);
    return pack(x, y);
  }
  const std::vector<cv::Point2f>& pts_;
  float cell_;
  std::unordered_map<long long, std::vector<int>> cells_;
};

}  // namespace

DynamicFeatureFilter::DynamicFeatureFilter(const MotionCheckConfig& cfg,
                                           const std::vector<std::string>& class_names)
    : cfg_(cfg) {
  always_dynamic_.assign(class_names.size(), false);
  for (const auto& n : cfg_.always_dynamic_classes) {
    const int id = class_index(class_names, n);
    if (id < 0)
      throw ConfigError("(motion check)", 0, "always_dynamic_classes", "unknown class name '" + n + "'");
    always_dynamic_[static_cast<std::size_t>(id)] = true;
  }
}

void DynamicFeatureFilter::reset() {
  history_.clear();
  tracks_.clear();
  cached_gray_.release();
  cached_pyr_.clear();
  stored_.clear();
}

namespace {

// Moves a box over one flow step by the flow of the points inside it; false (box unchanged) when fewer
// than 3 points are there to follow.
bool carry_box(cv::Rect2f& box, const std::vector<cv::Point2f>& prev, const std::vector<cv::Point2f>& cur) {
  std::vector<std::size_t> in;
  for (std::size_t i = 0; i < prev.size(); ++i) {
    if (inside(box, prev[i])) in.push_back(i);
  }
  if (in.size() < 3) return false;
  std::vector<float> px, py, cx, cy;
  for (std::size_t i : in) {
    px.push_back(prev[i].x), py.push_back(prev[i].y);
    cx.push_back(cur[i].x), cy.push_back(cur[i].y);
  }
  // The points' median moves by the median flow; the box also scales by the median change of
  // the points' distances to it (a person walking towards the camera grows between detections).
  const cv::Point2f c_prev(median_of(px), median_of(py)), c_cur(median_of(cx), median_of(cy));
  std::vector<float> ratios;
  for (std::size_t i : in) {
    const float r_prev = static_cast<float>(cv::norm(prev[i] - c_prev));
    if (r_prev > 8.f) ratios.push_back(static_cast<float>(cv::norm(cur[i] - c_cur)) / r_prev);
  }
  const float scale = ratios.size() >= 3 ? std::clamp(median_of(ratios), 0.8f, 1.25f) : 1.f;
  // The box corner keeps its offset from the points' median, scaled.
  box.x = c_cur.x + (box.x - c_prev.x) * scale;
  box.y = c_cur.y + (box.y - c_prev.y) * scale;
  box.width *= scale;
  box.height *= scale;
  return true;
}

// Share of the cells of an 8 x 6 grid over the image that hold a keypoint not culled.
double kept_coverage(const std::vector<cv::KeyPoint>& kps, const std::vector<bool>& culled,
                     const cv::Size& image) {
  constexpr int kCols = 8, kRows = 6;
  std::array<bool, kCols * kRows> cell{};
  for (std::size_t k = 0; k < kps.size(); ++k) {
    if (culled[k]) continue;
    const int c =
        std::clamp(static_cast<int>(kps[k].pt.x * kCols / static_cast<float>(image.width)), 0, kCols - 1);
    const int r =
        std::clamp(static_cast<int>(kps[k].pt.y * kRows / static_cast<float>(image.height)), 0, kRows - 1);
    cell[static_cast<std::size_t>(r * kCols + c)] = true;
  }
  return static_cast<double>(std::count(cell.begin(), cell.end(), true)) / (kCols * kRows);
}

// Moves each edge of the box that lies within `snap` px of the image's edge onto it.
void snap_to_border(cv::Rect2f& box, const cv::Size& image, float snap) {
  const auto w = static_cast<float>(image.width), h = static_cast<float>(image.height);
  float x0 = box.x, y0 = box.y, x1 = box.x + box.width, y1 = box.y + box.height;
  if (x0 < snap) x0 = 0.f;
  if (y0 < snap) y0 = 0.f;
  if (x1 > w - snap) x1 = w;
  if (y1 > h - snap) y1 = h;
  box = cv::Rect2f(x0, y0, x1 - x0, y1 - y0);
}

}  // namespace

std::vector<Detection> DynamicFeatureFilter::carry_boxes(const Detections& d, std::size_t to_frame) const {
  std::vector<Detection> out = d.items;
  for (const FlowStep& step : history_) {
    if (step.frame_index <= d.frame_index || step.frame_index > to_frame) continue;
    for (Detection& det : out) carry_box(det.box, step.prev, step.cur);
  }
  return out;
}

std::vector<Detection> DynamicFeatureFilter::coast_boxes(const std::vector<Detection>& detected,
                                                         std::size_t frame) const {
  std::vector<Detection> out;
  if (cfg_.coast_frames <= 0 || history_.empty() || history_.back().frame_index != frame) return out;
  const FlowStep& step = history_.back();
  for (const BoxTrack& t : tracks_) {
    // Followed up to the previous frame, eligible (moved lately; with coast_culled: culled in the frame
    // before), detected recently enough.
    const bool eligible =
        cfg_.coast_culled ? t.last_culled_frame == t.last_seen_frame
                          : t.last_dynamic_frame && frame - *t.last_dynamic_frame <=
                                                        static_cast<std::size_t>(cfg_.dynamic_hold_frames);
    if (t.last_seen_frame + 1 != frame || !eligible) continue;
    if (frame - t.last_detected_frame > static_cast<std::size_t>(cfg_.coast_frames)) continue;
    Detection det;
    det.box = t.box;
    det.class_id = t.class_id;
    det.score = 0.f;  // not a detection
    if (!carry_box(det.box, step.prev, step.cur)) continue;
    const bool covered = std::any_of(detected.begin(), detected.end(), [&](const Detection& d) {
      return d.class_id == det.class_id && iou(d.box, det.box) > 0.3f;
    });
    if (!covered) out.push_back(det);
  }
  return out;
}

DynamicResult DynamicFeatureFilter::process(const DynamicInput& in) {
  Stopwatch sw;
  DynamicResult res;
  res.residual_used = "none";
  if (in.gray == nullptr || in.gray->empty() || in.gray->type() != CV_8UC1) {
    throw Error("dynamic filter: the current image must be a non-empty CV_8UC1 Mat");
  }
  const cv::Mat& gray = *in.gray;
  const bool has_depth = in.depth != nullptr && !in.depth->empty();
  if (has_depth && (in.depth->type() != CV_32F || in.depth->size() != gray.size())) {
    throw Error("dynamic filter: depth must be CV_32F metres of the image's size");
  }
  const std::size_t n_kp = in.keypoints != nullptr ? in.keypoints->size() : 0;
  res.keypoint_dynamic.assign(n_kp, false);
  if (cfg_.mode == CullMode::kOff) {
    res.ms = sw.elapsed_ms();
    return res;
  }
  const bool use_boxes = cfg_.mode != CullMode::kFlowOnly;
  const bool has_prev = in.prev_gray != nullptr && !in.prev_gray->empty();
  if (has_prev && (in.prev_gray->size() != gray.size() || in.prev_gray->type() != CV_8UC1)) {
    throw Error("dynamic filter: previous image differs in size or type from the current one");
  }
  const bool do_flow = cfg_.mode != CullMode::kDetectorOnly && has_prev;

  // 1. Sparse flow, tracked backwards (cur -> prev) and checked forwards.
  std::vector<cv::Point2f>& cur = res.flow_points;
  std::vector<cv::Point2f>& prev = res.flow_prev;
  if (do_flow) {
    // Cells no smaller than needed to spread max_points over the image.
    const int cell =
        std::max(cfg_.grid_cell_px,
                 static_cast<int>(std::ceil(std::sqrt(static_cast<double>(gray.total()) / cfg_.max_points))));
    std::vector<cv::Point2f> cand =
        pick_points(gray, in.keypoints, cell, cfg_.max_points,
                    use_boxes && in.detections != nullptr ? in.detections->items : std::vector<Detection>{},
                    cfg_.box_points);
    if (!cand.empty()) {
      const cv::Size win(cfg_.lk_window, cfg_.lk_window);
      const cv::TermCriteria term(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 0.03);
      std::vector<cv::Mat> pyr_cur, pyr_prev;
      // No reuse of the input buffer: the pyramid is cached past this call.
      cv::buildOpticalFlowPyramid(gray, pyr_cur, win, cfg_.lk_levels, true, cv::BORDER_REFLECT_101,
                                  cv::BORDER_CONSTANT, false);
      // The previous frame's pyramid is last call's current one when the caller passes the same image.
      const cv::Mat& pg = *in.prev_gray;
      const bool same = !cached_gray_.empty() && cached_gray_.size() == pg.size() && pg.isContinuous() &&
                        std::memcmp(cached_gray_.data, pg.data, pg.total()) == 0;
      if (same) {
        pyr_prev = std::move(cached_pyr_);
      } else {
        cv::buildOpticalFlowPyramid(pg, pyr_prev, win, cfg_.lk_levels);
      }
      std::vector<cv::Point2f> back, fwd;
      std::vector<uchar> st1, st2;
      std::vector<float> err;
      cv::calcOpticalFlowPyrLK(pyr_cur, pyr_prev, cand, back, st1, err, win, cfg_.lk_levels, term);
      fwd = cand;
      cv::calcOpticalFlowPyrLK(pyr_prev, pyr_cur, back, fwd, st2, err, win, cfg_.lk_levels, term,
                               cv::OPTFLOW_USE_INITIAL_FLOW);
      gray.copyTo(cached_gray_);
      cached_pyr_ = pyr_cur;
      if (cfg_.used_person_baseline_frames > 1) {
        if (!stored_.empty() && stored_.back().frame_index + 1 != in.frame_index) stored_.clear();
        stored_.push_back({in.frame_index, pyr_cur, std::nullopt});
        while (static_cast<int>(stored_.size()) > cfg_.used_person_baseline_frames + 1) stored_.pop_front();
      }
      const cv::Rect2f image(0.f, 0.f, static_cast<float>(gray.cols), static_cast<float>(gray.rows));
      const auto fb2 = static_cast<float>(cfg_.fb_max_px * cfg_.fb_max_px);
      for (std::size_t i = 0; i < cand.size(); ++i) {
        const cv::Point2f d = fwd[i] - cand[i];
        if (st1[i] && st2[i] && d.dot(d) <= fb2 && inside(image, back[i])) {
          cur.push_back(cand[i]);
          prev.push_back(back[i]);
        }
      }
    }
    if (!stored_.empty() && stored_.back().frame_index != in.frame_index) stored_.clear();
    history_.push_back({in.frame_index, prev, cur});
    while (static_cast<int>(history_.size()) > cfg_.max_history_frames) history_.pop_front();
  } else if (!has_prev) {
    history_.clear();
    stored_.clear();
  }

  // 2. Candidate boxes, carried from the detection's frame to this one.
  if (use_boxes && in.detections != nullptr) res.boxes = carry_boxes(*in.detections, in.frame_index);
  const std::size_t n_detected = res.boxes.size();  // the boxes after these are coasted, not detected
  if (use_boxes && do_flow) {
    const std::vector<Detection> coasted = coast_boxes(res.boxes, in.frame_index);
    res.boxes.insert(res.boxes.end(), coasted.begin(), coasted.end());
  }
  if (cfg_.border_snap_px > 0.0) {
    for (Detection& d : res.boxes)
      snap_to_border(d.box, gray.size(), static_cast<float>(cfg_.border_snap_px));
  }
  const auto margin = static_cast<float>(cfg_.box_margin_px);
  const std::size_t n = cur.size();
  std::vector<bool> in_box(n, false);
  for (std::size_t i = 0; i < n; ++i) {
    for (const auto& b : res.boxes) in_box[i] = in_box[i] || inside(grow(b.box, margin), cur[i]);
  }

  // 3. Residual of each point after removing the camera's own motion.
  res.flow_residual.assign(n, -1.f);
  std::vector<bool> moving(n, false);
  std::optional<EgoFit> ego;                 // the motion the reprojection residuals were computed under
  std::vector<std::size_t> ego_fit_inliers;  // the fitted points that came out static (joint / span checks)
  if (n >= 8) {
    std::vector<int> fit;  // static candidates: outside the boxes
    for (std::size_t i = 0; i < n; ++i) {
      if (!in_box[i]) fit.push_back(static_cast<int>(i));
    }
    if (static_cast<int>(fit.size()) < cfg_.min_static_points) {
      fit.resize(n);
      for (std::size_t i = 0; i < n; ++i) fit[i] = static_cast<int>(i);
    }
    const bool want_reproj = cfg_.residual != "epipolar" && has_depth && in.K.has_value();
    if (cfg_.residual == "reprojection" && !want_reproj) {
      throw Error("dynamic filter: residual 'reprojection' needs depth and K");
    }
    std::vector<float> eps(n, 0.f);
    bool done = false;
    if (want_reproj) done = reprojection_residuals(in, fit, res, eps, &ego.emplace());
    if (!done) {
      ego.reset();
      epipolar_residuals(fit, res, eps);
    }
    for (std::size_t i = 0; i < n; ++i) moving[i] = res.flow_residual[i] > eps[i];
    if (ego && !stored_.empty() && stored_.back().frame_index == in.frame_index)
      stored_.back().motion = ego->motion;
    if (ego && (cfg_.joint_fit_still || cfg_.used_person_baseline_frames > 1)) {
      for (int i : fit) {
        const auto k = static_cast<std::size_t>(i);
        if (res.flow_residual[k] >= 0.f && !moving[k]) ego_fit_inliers.push_back(k);
      }
    }
    int fitted = 0, fitted_moving = 0;
    for (int i : fit) {
      if (res.flow_residual[static_cast<std::size_t>(i)] < 0.f) continue;
      ++fitted;
      fitted_moving += moving[static_cast<std::size_t>(i)] ? 1 : 0;
    }
    res.ego_motion_rejected = do_flow && fitted >= cfg_.min_static_points &&
                              static_cast<double>(fitted_moving) > cfg_.max_moving_share * fitted;
  }
  res.flow_point_moving = moving;
  // A rejected camera-motion fit: flow judges nothing this frame (classes decide, as without flow).
  const bool flow_judges = do_flow && !res.ego_motion_rejected;

  // 4. Which boxes move.
  res.box_dynamic.assign(res.boxes.size(), false);
  std::vector<float> object_depth(res.boxes.size(), 0.f);
  const auto bg_margin = static_cast<float>(cfg_.background_depth_margin_m);
  std::vector<bool> track_used(tracks_.size(), false);
  std::vector<bool> still_person(res.boxes.size(), false);  // proven still: culled unless needed
  std::vector<std::size_t> box_track(res.boxes.size());     // each box's track in tracks_
  for (std::size_t b = 0; b < res.boxes.size(); ++b) {
    const Detection& det = res.boxes[b];
    const bool always = det.class_id >= 0 &&
                        static_cast<std::size_t>(det.class_id) < always_dynamic_.size() &&
                        always_dynamic_[static_cast<std::size_t>(det.class_id)];
    std::vector<std::size_t> members;
    std::vector<float> member_z, z_moving, z_all;
    for (std::size_t i = 0; i < n; ++i) {
      if (!inside(det.box, cur[i]) || res.flow_residual[i] < 0.f) continue;
      // Depth-edge points are left out of the object depth: theirs may belong to the background.
      const float z = has_depth ? stable_depth(*in.depth, cur[i]) : 0.f;
      members.push_back(i);
      member_z.push_back(z);
      if (z > 0.f) (moving[i] ? z_moving : z_all).push_back(z);
    }
    // Object depth: the movers' median, else a low quantile (the object is in front of its background).
    if (z_moving.size() >= 3) {
      object_depth[b] = median_of(z_moving);
    } else {
      std::vector<float> z = z_all;
      z.insert(z.end(), z_moving.begin(), z_moving.end());
      object_depth[b] = z.size() >= 3 ? quantile_of(z, 0.3) : 0.f;
    }
    std::vector<std::size_t> depth_members;  // members within the margin of the object's depth
    for (std::size_t m = 0; m < members.size(); ++m) {
      if (member_z[m] > 0.f && std::abs(member_z[m] - object_depth[b]) <= bg_margin)
        depth_members.push_back(members[m]);
    }
    // The vote: over the points at the object's depth when there are enough, else over all of them.
    int total = 0, mov = 0;
    if (cfg_.ratio_at_object_depth && object_depth[b] > 0.f) {
      total = static_cast<int>(depth_members.size());
      for (std::size_t i : depth_members) mov += moving[i] ? 1 : 0;
    }
    if (total < cfg_.min_points_to_decide) {
      total = static_cast<int>(members.size());
      mov = 0;
      for (std::size_t i : members) mov += moving[i] ? 1 : 0;
    }
    enum class Seen { kMoving, kStill, kUndecided } seen = Seen::kUndecided;
    const bool judged = cfg_.mode != CullMode::kDetectorOnly && flow_judges;
    if (judged && total >= cfg_.min_points_to_decide) {
      seen = static_cast<double>(mov) >= cfg_.moving_ratio_threshold * static_cast<double>(total)
                 ? Seen::kMoving
                 : Seen::kStill;
    }
    // A person's still vote over few points is no proof (a handful of flow points on a walker can all
    // lie within the threshold): it counts as undecided, neither extending nor breaking the streak.
    if (seen == Seen::kStill && always && cfg_.static_proof_frames > 0 &&
        total < cfg_.min_points_to_prove_still)
      seen = Seen::kUndecided;
    if (seen == Seen::kMoving && cfg_.joint_fit_still && ego &&
        static_cast<int>(depth_members.size()) >= cfg_.min_points_to_decide &&
        explained_by_camera(*in.K, ego->motion, *ego, res.flow_prev, ego_fit_inliers, depth_members)) {
      seen = Seen::kStill;
    }
    // The same object in earlier frames: the unused track of its class with the largest overlap.
    std::size_t match = tracks_.size();
    float best_iou = 0.3f;
    for (std::size_t t = 0; t < tracks_.size(); ++t) {
      const float o = iou(tracks_[t].box, det.box);
      if (!track_used[t] && tracks_[t].class_id == det.class_id && o > best_iou) best_iou = o, match = t;
    }
    if (match == tracks_.size()) {
      BoxTrack fresh;
      fresh.box = det.box;
      fresh.class_id = det.class_id;
      fresh.last_seen_frame = fresh.last_detected_frame = in.frame_index;
      tracks_.push_back(fresh);
      track_used.push_back(false);
    }
    track_used[match] = true;
    box_track[b] = match;
    BoxTrack& track = tracks_[match];
    // A person in use lately is also judged over a longer span: the first steps of a walk are small.
    const auto span = static_cast<std::size_t>(cfg_.used_person_baseline_frames);
    if (seen == Seen::kStill && span > 1 && ego && track.last_used_frame &&
        in.frame_index - *track.last_used_frame <= span &&
        moved_over_baseline(in, res, *ego, ego_fit_inliers, depth_members).value_or(false)) {
      seen = Seen::kMoving;
    }
    track.box = det.box;
    track.last_seen_frame = in.frame_index;
    if (b < n_detected) track.last_detected_frame = in.frame_index;
    if (seen == Seen::kMoving) {
      track.last_dynamic_frame = in.frame_index;
      track.static_streak = 0;
    } else if (seen == Seen::kStill) {
      ++track.static_streak;
    } else if (judged && always && cfg_.static_proof_frames == 0) {
      // Too few points to judge: the class decides (the earlier rule), and counts as motion for the hold.
      track.last_dynamic_frame = in.frame_index;
    }
    // People pause mid-walk: a box that moved a moment ago keeps being dynamic for a while.
    const bool held = track.last_dynamic_frame && in.frame_index - *track.last_dynamic_frame <=
                                                      static_cast<std::size_t>(cfg_.dynamic_hold_frames);
    // Static until proven: an object of a dynamic class is dynamic until seen still long enough.
    const bool unproven =
        always && (cfg_.static_proof_frames == 0 ? seen == Seen::kUndecided
                                                 : track.static_streak < cfg_.static_proof_frames);
    bool dyn = false;
    if (cfg_.mode == CullMode::kDetectorOnly) {
      dyn = true;
    } else if (!flow_judges) {
      dyn = always;
    } else {
      dyn = seen == Seen::kMoving || held || unproven;
      still_person[b] = !dyn && always && cfg_.static_proof_frames > 0;
    }
    res.box_dynamic[b] = dyn || still_person[b];
    if (res.box_dynamic[b]) track.last_culled_frame = in.frame_index;
    spdlog::debug(
        "frame {} box {} (x {:.0f}-{:.0f}, class {}): seen {} ({} of {} moving), still streak {}{}{}{}",
        in.frame_index, b, det.box.x, det.box.x + det.box.width, det.class_id,
        seen == Seen::kMoving  ? "moving"
        : seen == Seen::kStill ? "still"
                               : "undecided",
        mov, total, track.static_streak, held ? ", held" : "", unproven ? ", unproven" : "",
        still_person[b] ? ", proven still" : "");
  }

  // 5. Confirmed movers: moving points with enough moving neighbours (isolated ones are noise).
  const bool cull_movers = flow_judges && (cfg_.mode == CullMode::kFlowOnly || cfg_.cull_unboxed_movers);
  std::vector<bool> confirmed(n, false);
  const PointGrid grid(cur, static_cast<float>(std::max(cfg_.cluster_radius_px, cfg_.unboxed_radius_px)));
  if (cull_movers) {
    for (std::size_t i = 0; i < n; ++i) {
      if (!moving[i]) continue;
      int near = 0;
      grid.for_each_near(cur[i], static_cast<float>(cfg_.cluster_radius_px),
                         [&](int j, float) { near += moving[static_cast<std::size_t>(j)] ? 1 : 0; });
      confirmed[i] = near >= cfg_.cluster_min_points;
    }
  }

  // 6. Keypoints: inside a dynamic box (unless depth-separated from the object), or nearest to a mover.
  //    Kept keypoints in or near an object are marked suspect for the tracker's pose guard.
  res.keypoint_suspect.assign(n_kp, false);
  const auto nearest_flow = [&](const cv::Point2f& p) {
    int nearest = -1;
    float best = std::numeric_limits<float>::max();
    grid.for_each_near(p, static_cast<float>(cfg_.unboxed_radius_px), [&](int j, float d2) {
      if (d2 < best) best = d2, nearest = j;
    });
    return nearest;
  };
  // Whether keypoint p lies at box b's object depth (within the margin); none without both depths.
  const auto at_object_depth = [&](std::size_t b, const cv::Point2f& p) -> std::optional<bool> {
    if (object_depth[b] <= 0.f) return std::nullopt;
    const float z = raw_depth(in.depth, p);
    if (z <= 0.f) return std::nullopt;
    return std::abs(z - object_depth[b]) <= bg_margin;
  };
  // Per box, the bands around it where keypoints at the object's depth are the object (culled) or only
  // suspect for the pose guard (0: none).
  const auto band_widths = [&](double share) {
    std::vector<float> w(res.boxes.size(), 0.f);
    if (share <= 0.0) return w;
    for (std::size_t b = 0; b < res.boxes.size(); ++b)
      w[b] = static_cast<float>(share) * std::max(res.boxes[b].box.width, res.boxes[b].box.height);
    return w;
  };
  const std::vector<float> band = band_widths(cfg_.object_band_share);
  const std::vector<float> suspect_band = band_widths(cfg_.suspect_band_share);
  // Whether keypoint p lies in a band `width` wide outside dynamic box b (beyond its margin), at the
  // object's depth. A band no wider than the margin holds nothing.
  const auto in_object_band = [&](std::size_t b, const cv::Point2f& p, float width) {
    const cv::Rect2f& box = res.boxes[b].box;
    return width > margin && res.box_dynamic[b] && inside(grow(box, width), p) &&
           !inside(grow(box, margin), p) && at_object_depth(b, p).value_or(false);
  };
  const auto classify = [&] {
    res.culled = 0;
    for (std::size_t k = 0; k < n_kp; ++k) {
      const cv::Point2f& p = (*in.keypoints)[k].pt;
      bool dyn = false;
      bool near_object = false;
      for (std::size_t b = 0; b < res.boxes.size() && !dyn; ++b) {
        const cv::Rect2f& box = res.boxes[b].box;
        if (in_object_band(b, p, band[b])) {
          dyn = near_object = true;
          continue;
        }
        if (!near_object && in_object_band(b, p, suspect_band[b])) near_object = true;
        if (!inside(grow(box, 2.f * margin), p)) continue;
        near_object = true;
        if (!res.box_dynamic[b] || !inside(grow(box, margin), p)) continue;
        // Depth-separated points in the box (background behind, furniture in front) are kept. No depth
        // (edges, projector shadow): culled, missing a mover costs more than a lost point.
        dyn = !cfg_.keep_background_in_box || at_object_depth(b, p).value_or(true);
      }
      if (!dyn && (cull_movers || flow_judges)) {
        const int j = nearest_flow(p);
        const bool mover_near = j >= 0 && moving[static_cast<std::size_t>(j)];
        dyn = cull_movers && j >= 0 && confirmed[static_cast<std::size_t>(j)];
        if (dyn && cfg_.unboxed_depth_separated && has_depth) {
          const float z = raw_depth(in.depth, p);
          const float z_mover = stable_depth(*in.depth, cur[static_cast<std::size_t>(j)]);
          if (z > 0.f && z_mover > 0.f && std::abs(z - z_mover) > bg_margin) dyn = false;
        }
        near_object = near_object || mover_near;
      }
      res.keypoint_dynamic[k] = dyn;
      res.keypoint_suspect[k] = !dyn && near_object;
      res.culled += dyn ? 1 : 0;
    }
  };
  classify();
  // People proven still are culled too while enough keypoints remain without them; only when the
  // rest of the image is too poor are their features used (marked suspect for the pose guard).
  const bool any_still = std::find(still_person.begin(), still_person.end(), true) != still_person.end();
  const bool poor =
      any_still && (static_cast<int>(n_kp) - res.culled < cfg_.still_people_fallback_keypoints ||
                    (cfg_.still_people_fallback_coverage > 0.0 && in.keypoints != nullptr &&
                     kept_coverage(*in.keypoints, res.keypoint_dynamic, gray.size()) <
                         cfg_.still_people_fallback_coverage));
  if (poor) {
    for (std::size_t b = 0; b < res.boxes.size(); ++b) {
      if (!still_person[b]) continue;
      res.box_dynamic[b] = false;
      tracks_[box_track[b]].last_used_frame = in.frame_index;
    }
    classify();
    res.still_people_released = true;
  } else if (any_still && cfg_.reserve_still_people) {
    // What a release would keep: classified again with the still people static, then restored.
    const std::vector<bool> culled = res.keypoint_dynamic;
    const std::vector<bool> suspect = res.keypoint_suspect;
    const std::vector<bool> box_dynamic = res.box_dynamic;
    const int culled_count = res.culled;
    for (std::size_t b = 0; b < res.boxes.size(); ++b)
      if (still_person[b]) res.box_dynamic[b] = false;
    classify();
    res.keypoint_reserve.assign(n_kp, false);
    for (std::size_t k = 0; k < n_kp; ++k) res.keypoint_reserve[k] = culled[k] && !res.keypoint_dynamic[k];
    res.keypoint_dynamic = culled;
    res.keypoint_suspect = suspect;
    res.box_dynamic = box_dynamic;
    res.culled = culled_count;
  }
  if (any_still)
    spdlog::debug("frame {}: proven-still people {}", in.frame_index, poor ? "released" : "culled");
  // After the release: box_track indexes tracks_.
  std::erase_if(tracks_, [&](const BoxTrack& t) {
    return in.frame_index > t.last_seen_frame + static_cast<std::size_t>(std::max(cfg_.dynamic_hold_frames,
                                                                                  cfg_.max_history_frames));
  });
  res.ms = sw.elapsed_ms();
  return res;
}

}  // namespace sp::dyn
