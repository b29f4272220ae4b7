#pragma once
// The live view of `stillpoint run --viewer [PORT]`: a small HTTP server on 127.0.0.1 that serves one
// page (the report's embedded three.js, no network access) and streams the run to it as Server-Sent
// Events. Events are JSON objects; the page understands
//   pose      {"frame", "t", "state", "p": [x y z], "q": [x y z w] (absent when not tracked), "culled"}
//   map       {"points": base64 float32 xyz, "count", "keyframes": base64 float32 xyz, "keyframe_count"}
//   overlay   {"jpeg": base64 JPEG of the frame with the culled features marked, "culled"}
//   end       {"frames", "tracked"}: the run finished; the page closes its stream
// A page that connects late first receives every pose so far and the latest map (history replay).
#include <atomic>
#include <cstddef>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "stillpoint/report/viewer_assets.hpp"

namespace sp::report {

class LiveViewServer {
 public:
  // Listens on 127.0.0.1:port (0: a free port, see port()). Throws sp::Error when it cannot.
  LiveViewServer(int port, const ViewerAssets& assets);
  ~LiveViewServer();
  LiveViewServer(const LiveViewServer&) = delete;
  LiveViewServer& operator=(const LiveViewServer&) = delete;

  [[nodiscard]] int port() const noexcept { return port_; }
  // Sends an event to every connected page (never blocks on a slow one: it is dropped) and keeps it
  // for pages that connect later (poses all, map and overlay the latest only).
  void publish(const std::string& type, const std::string& json);
  // Pages connected to the event stream now.
  [[nodiscard]] std::size_t clients() const;

 private:
  void serve();
  void handle(int fd);
  void send_event(int fd, const std::string& message);

  std::string page_;
  int listen_fd_ = -1;
  int port_ = 0;
  std::atomic<bool> stop_{false};
  mutable std::mutex mutex_;
  std::vector<int> clients_;
  std::vector<std::string> poses_;  // formatted events, replayed in order
  std::string map_, overlay_, end_;
  std::thread thread_;
};

// The page itself (exposed for tests): HTML with three.js and the live-view script.
std::string live_view_page(const ViewerAssets& assets);

// Standard base64 (for float arrays and JPEG images inside events).
std::string base64_encode(std::string_view bytes);

}  // namespace sp::report
