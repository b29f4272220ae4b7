// The live view of `run --viewer`: the server speaks HTTP and Server-Sent Events (replaying the run so
// far to a page that connects late), and in headless Chromium the page receives poses streamed after it
// connected and draws them.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>
#include <thread>

#include "../support/shared_data.hpp"
#include "browser.hpp"
#include "stillpoint/report/live_view.hpp"

namespace sp::report {
namespace {

// GET `path` from 127.0.0.1:port; reads until the server closes or `until` appears in the answer.
std::string http_get(int port, const std::string& path, const std::string& until = "") {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return "";
  }
  const std::string request = "GET " + path + " HTTP/1.1\r\nHost: localhost\r\n\r\n";
  (void)::send(fd, request.data(), request.size(), MSG_NOSIGNAL);
  timeval tv{5, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  std::string answer;
  char buf[4096];
  while (until.empty() || answer.find(until) == std::string::npos) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) break;
    answer.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fd);
  return answer;
}

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

std::string pose_json(int i) {
  const double a = 0.1 * i;
  return nlohmann::json{{"frame", i},
                        {"t", 0.1 * i},
                        {"state", "ok"},
                        {"culled", i % 7},
                        {"p", {std::cos(a), 0.2 * std::sin(3 * a), std::sin(a)}},
                        {"q", {0.0, 0.0, 0.0, 1.0}}}
      .dump();
}

TEST(LiveView, ServesThePageAndReplaysEventsToLateClients) {
  LiveViewServer server(0, ViewerAssets{});
  ASSERT_GT(server.port(), 0);
  for (int i = 0; i < 5; ++i) server.publish("pose", pose_json(i));
  server.publish("map", R"({"points":"","count":0,"keyframes":"","keyframe_count":0})");
  server.publish("map", R"({"points":"AAAA","count":1,"keyframes":"","keyframe_count":0})");  // latest wins

  const std::string page = http_get(server.port(), "/");
  EXPECT_EQ(page.rfind("HTTP/1.1 200 OK", 0), 0u) << page.substr(0, 200);
  EXPECT_NE(page.find("text/html"), std::string::npos);
  EXPECT_NE(page.find("new EventSource('/events')"), std::string::npos);
  EXPECT_NE(page.find("</html>"), std::string::npos);
  EXPECT_EQ(http_get(server.port(), "/nothing").rfind("HTTP/1.1 404", 0), 0u);

  // A late page gets every pose so far and the latest map, then live events.
  const std::string stream = http_get(server.port(), "/events", "\"count\":1");
  EXPECT_NE(stream.find("Content-Type: text/event-stream"), std::string::npos);
  EXPECT_EQ(count(stream, "event: pose\n"), 5u);
  EXPECT_EQ(count(stream, "event: map\n"), 1u);
  EXPECT_NE(stream.find("\"count\":1"), std::string::npos);
  EXPECT_EQ(stream.find("\"count\":0"), std::string::npos);
}

TEST(LiveView, PageInChromiumReceivesLivePosesAndDrawsThem) {
  if (!std::filesystem::exists(kChromium)) {
    if (sp::test::on_ci()) FAIL() << kChromium << " not installed on CI (scripts/setup.sh installs it)";
    GTEST_SKIP() << kChromium << " not installed (apt-get install chromium)";
  }
  if (!viewer_assets().available) GTEST_SKIP() << "built without three.js (npm missing at build time)";
  LiveViewServer server(0, viewer_assets());
  constexpr int kPoses = 40;
  // The run starts only once the page is connected, so every pose below travels live (not replayed).
  std::thread run([&] {
    for (int k = 0; k < 600 && server.clients() == 0; ++k)
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (server.clients() == 0) return;
    for (int i = 0; i < kPoses; ++i) {
      server.publish("pose", pose_json(i));
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    std::vector<float> xyz;
    for (int i = 0; i < 300; ++i)
      xyz.insert(xyz.end(), {std::cos(0.02f * i) * 2, 0.5f, std::sin(0.02f * i) * 2});
    server.publish("map",
                   nlohmann::json{{"points", base64_encode(std::string_view(
                                                 reinterpret_cast<const char*>(xyz.data()), xyz.size() * 4))},
                                  {"count", 300},
                                  {"keyframes", ""},
                                  {"keyframe_count", 0}}
                       .dump());
    server.publish("end", R"({"frames":40,"tracked":40})");
  });
  const auto scratch = std::filesystem::path(SP_TEST_TMP_DIR) / "report" / "live_view";
  std::filesystem::create_directories(scratch);
  const BrowserRun browser =
      open_in_chromium("http://127.0.0.1:" + std::to_string(server.port()) + "/", scratch);
  run.join();
  ASSERT_EQ(browser.status, 0) << "chromium failed:\n" << browser.log.substr(0, 4000);
  const auto errors = console_errors(browser.log);
  std::string joined;
  for (const auto& e : errors) joined += e + "\n";
  EXPECT_TRUE(errors.empty()) << joined;
  const std::string viewer = "id=\"viewer\"";
  EXPECT_EQ(attribute(browser.dom, viewer, "data-live-status"), "ended")
      << attribute(browser.dom, viewer, "data-live-error") << "\n"
      << browser.log.substr(0, 3000);
  EXPECT_EQ(attribute(browser.dom, viewer, "data-poses"), std::to_string(kPoses));
  EXPECT_EQ(attribute(browser.dom, viewer, "data-trajectory-points"), std::to_string(kPoses));
  EXPECT_EQ(attribute(browser.dom, viewer, "data-map-points"), "300");
  const std::string pixels = attribute(browser.dom, viewer, "data-trajectory-pixels");
  ASSERT_FALSE(pixels.empty());
  EXPECT_GT(std::stol(pixels), 100) << "the streamed trajectory covered almost no pixel";
}

}  // namespace
}  // namespace sp::report
