#include "stillpoint/features/quadtree.hpp"

#include <algorithm>
#include <cmath>

namespace sp::feat {
namespace {

using Node = QuadtreeScratch::Node;

// Strict total order "a is better than b": higher response, then smaller y, then smaller x.
bool better(const cv::KeyPoint& a, const cv::KeyPoint& b) {
  if (a.response != b.response) return a.response > b.response;
  if (a.pt.y != b.pt.y) return a.pt.y < b.pt.y;
  return a.pt.x < b.pt.x;
}

// Splits `n` into up to four non-empty children appended to `dst`.
void split(const Node& n, const std::vector<cv::KeyPoint>& kps, std::vector<int>& order,
           std::vector<Node>& dst) {
  const float mx = 0.5f * (n.x0 + n.x1);
  const float my = 0.5f * (n.y0 + n.y1);
  int* b = order.data() + n.begin;
  int* e = order.data() + n.end;
  int* ym = std::partition(b, e, [&](int i) { return kps[static_cast<std::size_t>(i)].pt.y < my; });
  int* xm_top = std::partition(b, ym, [&](int i) { return kps[static_cast<std::size_t>(i)].pt.x < mx; });
  int* xm_bot = std::partition(ym, e, [&](int i) { return kps[static_cast<std::size_t>(i)].pt.x < mx; });
  const int base = n.begin;
  const auto idx = [&](const int* p) { return base + static_cast<int>(p - b); };
  const Node children[4] = {{n.x0, n.y0, mx, my, idx(b), idx(xm_top)},
                            {mx, n.y0, n.x1, my, idx(xm_top), idx(ym)},
                            {n.x0, my, mx, n.y1, idx(ym), idx(xm_bot)},
                            {mx, my, n.x1, n.y1, idx(xm_bot), idx(e)}};
  for (const Node& c : children) {
    if (c.end > c.begin) dst.push_back(c);
  }
}

}  // namespace

void distribute_quadtree(const std::vector<cv::KeyPoint>& kps, int target, float x0, float y0, float x1,
                         float y1, std::vector<cv::KeyPoint>& out, QuadtreeScratch& s) {
  out.clear();
  if (kps.empty() || target <= 0) return;
  s.order.clear();
  for (int i = 0; i < static_cast<int>(kps.size()); ++i) {
    const cv::Point2f& p = kps[static_cast<std::size_t>(i)].pt;
    if (p.x >= x0 && p.x < x1 && p.y >= y0 && p.y < y1) s.order.push_back(i);
  }
  if (s.order.empty()) return;

  // Roots: about square cells side by side (a wide image starts with several).
  const float w = x1 - x0, h = y1 - y0;
  const int n_roots = std::max(1, static_cast<int>(std::lround(w / h)));
  const float root_w = w / static_cast<float>(n_roots);
  s.nodes.clear();
  if (n_roots == 1) {
    s.nodes.push_back({x0, y0, x1, y1, 0, static_cast<int>(s.order.size())});
  } else {
    // Stable grouping of the indices by root column.
    const auto root_of = [&](int i) {
      const float rx = (kps[static_cast<std::size_t>(i)].pt.x - x0) / root_w;
      return std::min(n_roots - 1, static_cast<int>(rx));
    };
    std::stable_sort(s.order.begin(), s.order.end(), [&](int a, int b) { return root_of(a) < root_of(b); });
    int begin = 0;
    const int total = static_cast<int>(s.order.size());
    for (int r = 0; r < n_roots; ++r) {
      int end = begin;
      while (end < total && root_of(s.order[static_cast<std::size_t>(end)]) == r) ++end;
      const float rx0 = x0 + root_w * static_cast<float>(r);
      const float rx1 = r + 1 == n_roots ? x1 : x0 + root_w * static_cast<float>(r + 1);
      if (end > begin) s.nodes.push_back({rx0, y0, rx1, y1, begin, end});
      begin = end;
    }
  }

  const auto count = [](const Node& n) { return n.end - n.begin; };
  const auto target_sz = static_cast<std::size_t>(target);
  // Breadth-first rounds keep leaves of equal size (a regular grid) while they fit the target.
  while (s.nodes.size() < target_sz) {
    std::size_t expandable = 0;
    for (const Node& n : s.nodes) expandable += count(n) > 1 ? 1 : 0;
    if (expandable == 0) break;
    if (s.nodes.size() + 3 * expandable > target_sz) {
      // Last step: split the most crowded leaves first until the target is reached (a max-heap
      // on the count; ties by position so that the result is deterministic).
      const auto less_crowded = [&](const Node& a, const Node& b) {
        if (count(a) != count(b)) return count(a) < count(b);
        if (a.y0 != b.y0) return a.y0 > b.y0;
        return a.x0 > b.x0;
      };
      std::make_heap(s.nodes.begin(), s.nodes.end(), less_crowded);
      while (s.nodes.size() < target_sz && count(s.nodes.front()) > 1) {
        std::pop_heap(s.nodes.begin(), s.nodes.end(), less_crowded);
        const Node top = s.nodes.back();
        s.nodes.pop_back();
        s.next.clear();
        split(top, kps, s.order, s.next);
        for (const Node& c : s.next) {
          s.nodes.push_back(c);
          std::push_heap(s.nodes.begin(), s.nodes.end(), less_crowded);
        }
      }
      break;
    }
    s.next.clear();
    for (const Node& n : s.nodes) {
      if (count(n) > 1) {
        split(n, kps, s.order, s.next);
      } else {
        s.next.push_back(n);
      }
    }
    std::swap(s.nodes, s.next);
  }

  // The strongest keypoint of each leaf; trim to the target when the last split overshot.
  s.picked.clear();
  for (const Node& n : s.nodes) {
    int best = s.order[static_cast<std::size_t>(n.begin)];
    for (int k = n.begin + 1; k < n.end; ++k) {
      const int c = s.order[static_cast<std::size_t>(k)];
      if (better(kps[static_cast<std::size_t>(c)], kps[static_cast<std::size_t>(best)])) best = c;
    }
    s.picked.push_back(best);
  }
  std::sort(s.picked.begin(), s.picked.end(), [&](int a, int b) {
    return better(kps[static_cast<std::size_t>(a)], kps[static_cast<std::size_t>(b)]);
  });
  if (s.picked.size() > target_sz) s.picked.resize(target_sz);
  out.reserve(s.picked.size());
  for (int i : s.picked) out.push_back(kps[static_cast<std::size_t>(i)]);
}

}  // namespace sp::feat
