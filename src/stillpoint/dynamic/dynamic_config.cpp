#include "stillpoint/common/error.hpp"
#include "stillpoint/dynamic/dynamic_filter.hpp"

namespace sp::dyn {

CullMode parse_cull_mode(const std::string& s) {
  // The CLI spellings (flow, detector, detector+flow) are accepted too.
  if (s == "off") return CullMode::kOff;
  if (s == "detector_only" || s == "detector") return CullMode::kDetectorOnly;
  if (s == "flow_only" || s == "flow") return CullMode::kFlowOnly;
  if (s == "detector_flow" || s == "detector+flow") return CullMode::kDetectorFlow;
  throw Error("unknown dynamic culling mode '" + s + "' (off | detector_only | flow_only | detector_flow)");
}

const char* to_string(CullMode m) {
  switch (m) {
    case CullMode::kOff:
      return "off";
    case CullMode::kDetectorOnly:
      return "detector_only";
    case CullMode::kFlowOnly:
      return "flow_only";
    case CullMode::kDetectorFlow:
      return "detector_flow";
  }
  return "?";
}

MotionCheckConfig MotionCheckConfig::from_yaml(const ConfigReader& r) {
  MotionCheckConfig c;
  std::string mode = to_string(c.mode);
  r.read_choice("mode", mode,
                {"off", "detector_only", "flow_only", "detector_flow", "detector", "flow", "detector+flow"});
  c.mode = parse_cull_mode(mode);
  r.read_choice("residual", c.residual, {"auto", "epipolar", "reprojection"});
  r.read("lk_window", c.lk_window, 5, 61);
  r.read("lk_levels", c.lk_levels, 0, 6);
  r.read("max_points", c.max_points, 20, 5000);
  r.read("grid_cell_px", c.grid_cell_px, 4, 200);
  r.read("box_points", c.box_points, 0, 500);
  r.read("fb_max_px", c.fb_max_px, 0.1, 10.0);
  r.read("epsilon_epipolar_px", c.epsilon_epipolar_px, 0.1, 20.0);
  r.read("epsilon_reprojection_px", c.epsilon_reprojection_px, 0.1, 50.0);
  r.read("ransac_threshold_px", c.ransac_threshold_px, 0.1, 20.0);
  r.read("ransac_confidence", c.ransac_confidence, 0.5, 0.9999);
  r.read_choice("ego_fit", c.ego_fit, {"ransac", "msac"});
  r.read("ego_fit_flat_points", c.ego_fit_flat_points);
  r.read("depthless_homography", c.depthless_homography);
  r.read("ego_fit_threshold_px", c.ego_fit_threshold_px, 0.0, 50.0);
  r.read("ransac_iterations", c.ransac_iterations, 10, 10000);
  r.read("min_static_points", c.min_static_points, 8, 1000);
  r.read("moving_ratio_threshold", c.moving_ratio_threshold, 0.0, 1.0);
  r.read("min_points_to_decide", c.min_points_to_decide, 1, 1000);
  r.read("always_dynamic_classes", c.always_dynamic_classes);
  r.read("dynamic_hold_frames", c.dynamic_hold_frames, 0, 1000);
  r.read("static_proof_frames", c.static_proof_frames, 0, 1000);
  r.read("min_points_to_prove_still", c.min_points_to_prove_still, 1, 1000);
  r.read("still_people_fallback_keypoints", c.still_people_fallback_keypoints, 0, 100000);
  r.read("still_people_fallback_coverage", c.still_people_fallback_coverage, 0.0, 1.0);
  r.read("reserve_still_people", c.reserve_still_people);
  r.read("joint_fit_still", c.joint_fit_still);
  r.read("joint_fit_max_change_m", c.joint_fit_max_change_m, 0.0, 1.0);
  r.read("joint_fit_max_change_deg", c.joint_fit_max_change_deg, 0.0, 45.0);
  r.read("used_person_baseline_frames", c.used_person_baseline_frames, 0, 30);
  r.read("ratio_at_object_depth", c.ratio_at_object_depth);
  r.read("keep_background_in_box", c.keep_background_in_box);
  r.read("background_depth_margin_m", c.background_depth_margin_m, 0.05, 10.0);
  r.read("object_band_share", c.object_band_share, 0.0, 1.0);
  r.read("suspect_band_share", c.suspect_band_share, 0.0, 1.0);
  r.read("cull_unboxed_movers", c.cull_unboxed_movers);
  r.read("unboxed_depth_separated", c.unboxed_depth_separated);
  r.read("max_moving_share", c.max_moving_share, 0.05, 1.0);
  r.read("unboxed_radius_px", c.unboxed_radius_px, 1.0, 200.0);
  r.read("cluster_radius_px", c.cluster_radius_px, 1.0, 500.0);
  r.read("cluster_min_points", c.cluster_min_points, 1, 100);
  r.read("box_margin_px", c.box_margin_px, 0.0, 100.0);
  r.read("border_snap_px", c.border_snap_px, 0.0, 200.0);
  r.read("max_history_frames", c.max_history_frames, 1, 100);
  r.read("coast_frames", c.coast_frames, 0, 100);
  r.read("coast_culled", c.coast_culled);
  return c;
}

}  // namespace sp::dyn
