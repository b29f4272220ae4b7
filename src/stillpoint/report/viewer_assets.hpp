#pragma once
// The JavaScript that report.html needs for its 3-D view, compiled into the binary so a report never
// loads anything at view time. The definition is generated at build time (src/stillpoint/report/
// CMakeLists.txt): from the npm package `three` by web/viewer/embed.mjs, or an empty fallback when
// the build had no npm.
#include <string_view>

namespace sp::report {

struct ViewerAssets {
  bool available = false;          // false: built without three.js
  std::string_view three_version;  // e.g. "0.170.0"
  // three.module.min.js and OrbitControls.js as JavaScript string literals (quotes included, '<' and
  // non-ASCII escaped), so they can sit inside a <script> element and be imported from blob: URLs.
  std::string_view three_js_string;
  std::string_view orbit_controls_js_string;
  std::string_view viewer_js;  // web/viewer/viewer.js, the body of a module script
};

ViewerAssets viewer_assets();

}  // namespace sp::report
