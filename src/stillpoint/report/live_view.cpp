#include "stillpoint/report/live_view.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>

#include "stillpoint/common/error.hpp"

namespace sp::report {

namespace {

// The live page's script: three.js from the embedded strings (as the report's viewer.js), then an
// EventSource on /events. State for people and tests on #viewer: data-live-status = connecting | live |
// ended | error, data-poses = pose events received, data-trajectory-points = vertices of the drawn
// trajectory, data-map-points = map points drawn, data-overlays = overlay images shown,
// data-trajectory-pixels = pixels the trajectory covered when rendered alone (checked on "end").
constexpr const char* kLiveScript = R"JS(
const root = document.getElementById('viewer');
const status = document.getElementById('live-status');
const overlay = document.getElementById('overlay');
function fail(reason) {
  root.dataset.liveStatus = 'error';
  root.dataset.liveError = reason;
  status.textContent = 'live view unavailable: ' + reason;
  console.warn('StillPoint live view: ' + reason);
}
function decodeFloats(b64) {
  const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  return new Float32Array(bytes.buffer);
}
async function loadThree() {
  const threeUrl = URL.createObjectURL(new Blob([window.SP_THREE_SRC], { type: 'text/javascript' }));
  const THREE = await import(threeUrl);
  const orbitSrc = window.SP_ORBIT_SRC.replace(/from\s*['"]three['"]/g, "from '" + threeUrl + "'");
  const { OrbitControls } = await import(URL.createObjectURL(new Blob([orbitSrc], { type: 'text/javascript' })));
  return { THREE, OrbitControls };
}
async function main() {
  root.dataset.poses = '0';
  root.dataset.trajectoryPoints = '0';
  root.dataset.mapPoints = '0';
  root.dataset.overlays = '0';
  if (typeof window.SP_THREE_SRC !== 'string') return fail('built without three.js');
  const probe = document.createElement('canvas');
  if (!(probe.getContext('webgl2') || probe.getContext('webgl'))) return fail('WebGL is not available');
  const { THREE, OrbitControls } = await loadThree();
  const width = root.clientWidth || 800, height = root.clientHeight || 520;
  const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(width, height);
  renderer.setClearColor(0x11161c, 1);
  root.appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(50, width / height, 0.01, 1000);
  camera.up.set(0, -1, 0);  // SLAM world = first camera: y points down
  camera.position.set(0, -1.5, -3);
  camera.lookAt(0, 0, 1);
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.target.set(0, 0, 1);
  controls.update();
  const MAX = 200000;
  const traj = new Float32Array(3 * MAX);
  const trajGeom = new THREE.BufferGeometry();
  trajGeom.setAttribute('position', new THREE.BufferAttribute(traj, 3));
  trajGeom.setDrawRange(0, 0);
  const trajLine = new THREE.Line(trajGeom, new THREE.LineBasicMaterial({ color: '#ff7a1a' }));
  scene.add(trajLine);
  const mapGeom = new THREE.BufferGeometry();
  const mapPts = new THREE.Points(mapGeom, new THREE.PointsMaterial({ size: 2, sizeAttenuation: false, color: '#bbbbbb' }));
  scene.add(mapPts);
  const kfGeom = new THREE.BufferGeometry();
  scene.add(new THREE.Points(kfGeom, new THREE.PointsMaterial({ size: 6, sizeAttenuation: false, color: '#4aa3ff' })));
  const cam = new THREE.Mesh(new THREE.ConeGeometry(0.05, 0.12, 4), new THREE.MeshBasicMaterial({ color: '#ffffff', wireframe: true }));
  cam.geometry.rotateX(-Math.PI / 2);  // the cone looks along +z, as a camera does
  scene.add(cam);
  let n = 0, pending = false, ended = false;
  const render = () => { pending = false; renderer.render(scene, camera); };
  const schedule = () => { if (!pending) { pending = true; requestAnimationFrame(render); } };
  controls.addEventListener('change', schedule);
  root.dataset.liveStatus = 'connecting';
  const events = new EventSource('/events');
  events.onopen = () => {
    // (Re)connected: the server replays the whole run so far, so start the path afresh.
    n = 0;
    root.dataset.poses = '0';
    trajGeom.setDrawRange(0, 0);
    if (!ended) { root.dataset.liveStatus = 'live'; status.textContent = 'live'; }
  };
  events.addEventListener('pose', (ev) => {
    const e = JSON.parse(ev.data);
    root.dataset.poses = String(Number(root.dataset.poses) + 1);
    status.textContent = `frame ${e.frame}  t ${e.t.toFixed(3)} s  ${e.state}  culled ${e.culled}`;
    if (!e.p || n >= MAX) return;
    traj.set(e.p, 3 * n);
    ++n;
    trajGeom.setDrawRange(0, n);
    trajGeom.attributes.position.needsUpdate = true;
    trajGeom.computeBoundingSphere();
    root.dataset.trajectoryPoints = String(n);
    cam.position.set(e.p[0], e.p[1], e.p[2]);
    cam.quaternion.set(e.q[0], e.q[1], e.q[2], e.q[3]);
    schedule();
  });
  events.addEventListener('map', (ev) => {
    const e = JSON.parse(ev.data);
    mapGeom.setAttribute('position', new THREE.BufferAttribute(decodeFloats(e.points), 3));
    kfGeom.setAttribute('position', new THREE.BufferAttribute(decodeFloats(e.keyframes), 3));
    mapGeom.computeBoundingSphere();
    kfGeom.computeBoundingSphere();
    root.dataset.mapPoints = String(e.count);
    schedule();
  });
  events.addEventListener('overlay', (ev) => {
    const e = JSON.parse(ev.data);
    overlay.src = 'data:image/jpeg;base64,' + e.jpeg;
    root.dataset.overlays = String(Number(root.dataset.overlays) + 1);
  });
  events.addEventListener('end', (ev) => {
    const e = JSON.parse(ev.data);
    ended = true;
    events.close();
    // Self-check as in the report: the trajectory alone, pixels it covered.
    mapPts.visible = false;
    render();
    const gl = renderer.getContext();
    const px = new Uint8Array(width * height * 4);
    gl.readPixels(0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, px);
    let drawn = 0;
    for (let i = 0; i < px.length; i += 4)
      if (Math.abs(px[i] - 0x11) + Math.abs(px[i + 1] - 0x16) + Math.abs(px[i + 2] - 0x1c) > 30) ++drawn;
    mapPts.visible = true;
    render();
    root.dataset.trajectoryPixels = String(drawn);
    root.dataset.liveStatus = 'ended';
    status.textContent = `run finished: ${e.frames} frames, ${e.tracked} tracked`;
  });
  events.onerror = () => { if (!ended) { root.dataset.liveStatus = 'connecting'; status.textContent = 'reconnecting...'; } };
}
main().catch((e) => fail(String(e)));
)JS";

constexpr const char* kStyle =
    "body{font:14px sans-serif;margin:0;background:#0b0f14;color:#ddd}"
    "header{padding:8px 14px}#wrap{display:flex;gap:8px;padding:0 8px}"
    "#viewer{flex:1;height:520px;background:#11161c;position:relative}"
    "#viewer canvas{display:block;width:100%;height:100%}#side{width:330px}"
    "#overlay{width:320px;background:#222;min-height:240px}";

bool send_all(int fd, const std::string& data, bool wait) {
  std::size_t sent = 0;
  while (sent < data.size()) {
    const ssize_t n =
        ::send(fd, data.data() + sent, data.size() - sent, MSG_NOSIGNAL | (wait ? 0 : MSG_DONTWAIT));
    if (n <= 0) {
      if (n < 0 && errno == EINTR) continue;
      return false;
    }
    sent += static_cast<std::size_t>(n);
  }
  return true;
}

std::string format_event(const std::string& type, const std::string& json) {
  return "event: " + type + "\ndata: " + json + "\n\n";
}

}  // namespace

std::string base64_encode(std::string_view bytes) {
  static constexpr char kTable[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const auto v = (static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i])) << 16) |
                   (static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i + 1])) << 8) |
                   static_cast<unsigned char>(bytes[i + 2]);
    out += kTable[(v >> 18) & 63];
    out += kTable[(v >> 12) & 63];
    out += kTable[(v >> 6) & 63];
    out += kTable[v & 63];
  }
  if (i < bytes.size()) {
    std::uint32_t v = static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i])) << 16;
    if (i + 1 < bytes.size()) v |= static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i + 1])) << 8;
    out += kTable[(v >> 18) & 63];
    out += kTable[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? kTable[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

std::string live_view_page(const ViewerAssets& assets) {
  std::string h =
      "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>StillPoint live</title>"
      "<link rel=\"icon\" href=\"data:,\"><style>";
  h += kStyle;
  h += "</style></head><body>\n<header><b>StillPoint live view</b> &mdash; <span id=\"live-status\">"
       "connecting</span></header>\n<div id=\"wrap\"><div id=\"viewer\" data-live-status=\"pending\"></div>"
       "<div id=\"side\"><img id=\"overlay\" alt=\"current frame, culled features in red\"><p>Orange: "
       "camera path; blue: keyframes; grey: map points; red dots on the frame: features culled as "
       "moving.</p></div></div>\n";
  if (assets.available) {
    h += "<script>window.SP_THREE_SRC = " + std::string(assets.three_js_string) +
         ";\nwindow.SP_ORBIT_SRC = " + std::string(assets.orbit_controls_js_string) + ";</script>\n";
  }
  h += "<script type=\"module\">" + std::string(kLiveScript) + "</script>\n</body></html>\n";
  return h;
}

LiveViewServer::LiveViewServer(int port, const ViewerAssets& assets) : page_(live_view_page(assets)) {
  listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (listen_fd_ < 0) throw Error(std::string("live view: socket: ") + std::strerror(errno));
  const int one = 1;
  ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);  // localhost only: the stream is not for the network
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
      ::listen(listen_fd_, 16) != 0) {
    const std::string why = std::strerror(errno);
    ::close(listen_fd_);
    throw Error("live view: cannot listen on 127.0.0.1:" + std::to_string(port) + ": " + why);
  }
  socklen_t len = sizeof addr;
  ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
  port_ = ntohs(addr.sin_port);
  thread_ = std::thread([this] { serve(); });
}

LiveViewServer::~LiveViewServer() {
  stop_ = true;
  thread_.join();
  ::close(listen_fd_);
  std::lock_guard lock(mutex_);
  for (int fd : clients_) ::close(fd);
}

std::size_t LiveViewServer::clients() const {
  std::lock_guard lock(mutex_);
  return clients_.size();
}

void LiveViewServer::publish(const std::string& type, const std::string& json) {
  const std::string message = format_event(type, json);
  std::lock_guard lock(mutex_);
  if (type == "pose") {
    poses_.push_back(message);
  } else if (type == "map") {
    map_ = message;
  } else if (type == "overlay") {
    overlay_ = message;
  } else if (type == "end") {
    end_ = message;
  }
  // A page that cannot take the event now (full socket buffer) is dropped; it reconnects and replays.
  std::erase_if(clients_, [&](int fd) {
    if (send_all(fd, message, false)) return false;
    ::close(fd);
    return true;
  });
}

void LiveViewServer::serve() {
  while (!stop_) {
    pollfd p{listen_fd_, POLLIN, 0};
    if (::poll(&p, 1, 100) <= 0) continue;
    const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (fd < 0) continue;
    handle(fd);
  }
}

void LiveViewServer::handle(int fd) {
  // The request line is enough: GET / or GET /events (headers are read and ignored).
  std::string request;
  char buf[2048];
  while (request.find("\r\n\r\n") == std::string::npos && request.size() < 16384) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 2000) <= 0) break;
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) break;
    request.append(buf, static_cast<std::size_t>(n));
  }
  const auto path_start = request.find(' ');
  const auto path_end = path_start == std::string::npos ? path_start : request.find(' ', path_start + 1);
  const std::string path =
      path_end == std::string::npos ? "" : request.substr(path_start + 1, path_end - path_start - 1);
  if (request.rfind("GET ", 0) == 0 && path == "/events") {
    const std::string head =
        "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-cache\r\n"
        "Connection: keep-alive\r\n\r\nretry: 1000\n\n";
    std::lock_guard lock(mutex_);
    std::string replay = head;
    for (const auto& e : poses_) replay += e;
    replay += map_ + overlay_ + end_;
    if (send_all(fd, replay, true)) {
      clients_.push_back(fd);
    } else {
      ::close(fd);
    }
    return;
  }
  const bool page = request.rfind("GET ", 0) == 0 && (path == "/" || path == "/index.html");
  const std::string body = page ? page_ : "not found\n";
  const std::string head = std::string(page ? "HTTP/1.1 200 OK" : "HTTP/1.1 404 Not Found") +
                           "\r\nContent-Type: " + (page ? "text/html; charset=utf-8" : "text/plain") +
                           "\r\nContent-Length: " + std::to_string(body.size()) +
                           "\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n";
  send_all(fd, head + body, true);
  ::close(fd);
}

}  // namespace sp::report
