// The 3-D view of report.html (embedded by `stillpoint report` as a module script).
// three.js and OrbitControls arrive as strings (window.SP_THREE_SRC / SP_ORBIT_SRC) and are imported
// from blob: URLs, so the page stays one file and loads nothing from the network.
// Outcome for people and for tests, on #viewer: data-viewer-status = ok | error | unavailable,
// data-trajectory-points = vertices of the estimated trajectory in the scene, data-trajectory-pixels =
// pixels it covered when rendered alone, data-viewer-error = the reason on failure.
const root = document.getElementById('viewer');

function fail(reason) {
  root.dataset.viewerStatus = 'error';
  root.dataset.viewerError = reason;
  root.innerHTML = '';
  const msg = document.createElement('div');
  msg.className = 'viewer-msg';
  msg.textContent = '3-D view unavailable: ' + reason;
  root.appendChild(msg);
  // A warning, not an error: a browser without WebGL is an expected case, not a bug in the page.
  console.warn('StillPoint report: ' + msg.textContent);
}

function decodeFloats(b64) {
  const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  return new Float32Array(bytes.buffer);
}
function decodeBytes(b64) {
  return Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
}

function webglAvailable() {
  try {
    const c = document.createElement('canvas');
    return !!(c.getContext('webgl2') || c.getContext('webgl'));
  } catch (e) {
    return false;
  }
}

async function loadThree() {
  const threeUrl = URL.createObjectURL(new Blob([window.SP_THREE_SRC], { type: 'text/javascript' }));
  const THREE = await import(threeUrl);
  // OrbitControls imports the bare specifier 'three'; point it at the blob instead.
  const orbitSrc = window.SP_ORBIT_SRC.replace(/from\s*['"]three['"]/g, "from '" + threeUrl + "'");
  const orbitUrl = URL.createObjectURL(new Blob([orbitSrc], { type: 'text/javascript' }));
  const { OrbitControls } = await import(orbitUrl);
  return { THREE, OrbitControls };
}

function line(THREE, xyz, colour) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(xyz, 3));
  return new THREE.Line(g, new THREE.LineBasicMaterial({ color: colour }));
}

function points(THREE, cloud, size, fallbackColour) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(decodeFloats(cloud.xyz), 3));
  const m = new THREE.PointsMaterial({ size: size, sizeAttenuation: false });
  if (cloud.rgb) {
    g.setAttribute('color', new THREE.BufferAttribute(decodeBytes(cloud.rgb), 3, true));
    m.vertexColors = true;
  } else {
    m.color = new THREE.Color(fallbackColour);
  }
  return new THREE.Points(g, m);
}

// Extent of what the page shows: the trajectories in full, the clouds between their 2nd and 98th
// percentiles per axis (a map has far outliers). Returns centre and radius.
function extent(trajectories, clouds) {
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (const a of trajectories) {
    for (let i = 0; i + 2 < a.length; i += 3) {
      for (let k = 0; k < 3; ++k) {
        lo[k] = Math.min(lo[k], a[i + k]);
        hi[k] = Math.max(hi[k], a[i + k]);
      }
    }
  }
  for (const a of clouds) {
    const n = Math.floor(a.length / 3);
    if (n < 10) continue;
    const step = Math.max(1, Math.floor(n / 5000));
    for (let k = 0; k < 3; ++k) {
      const v = [];
      for (let i = 0; i < n; i += step) v.push(a[3 * i + k]);
      v.sort((x, y) => x - y);
      lo[k] = Math.min(lo[k], v[Math.floor(0.02 * (v.length - 1))]);
      hi[k] = Math.max(hi[k], v[Math.floor(0.98 * (v.length - 1))]);
    }
  }
  const centre = [0, 1, 2].map((k) => (lo[k] + hi[k]) / 2);
  const radius = Math.max(0.25, Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2);
  return { centre, radius };
}

async function main() {
  const data = JSON.parse(document.getElementById('sp-viewer-data').textContent);
  document.getElementById('viewer-frame').textContent = data.frame;
  if (typeof window.SP_THREE_SRC !== 'string') {
    fail('built without three.js');
    return;
  }
  if (data.estimate.count < 2) {
    fail('fewer than two estimated poses: no trajectory to draw');
    return;
  }
  if (!webglAvailable()) {
    fail('WebGL is not available in this browser');
    return;
  }
  const { THREE, OrbitControls } = await loadThree();

  const width = root.clientWidth || 800;
  const height = root.clientHeight || 560;
  // preserveDrawingBuffer: the self-check below reads the pixels back after rendering.
  const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(width, height);
  renderer.setClearColor(0x11161c, 1);
  root.innerHTML = '';
  root.appendChild(renderer.domElement);

  const scene = new THREE.Scene();
  const layers = {};
  const estXyz = decodeFloats(data.estimate.xyz);
  layers.estimate = line(THREE, estXyz, data.colours.estimate);
  const trajArrays = [estXyz];
  if (data.groundtruth) {
    const gtXyz = decodeFloats(data.groundtruth.xyz);
    layers.groundtruth = line(THREE, gtXyz, data.colours.groundtruth);
    trajArrays.push(gtXyz);
  }
  if (data.keyframes) {
    layers.keyframes = points(THREE, { xyz: data.keyframes.xyz }, 5, data.colours.keyframes);
  }
  if (data.map) layers.map = points(THREE, data.map, 2, '#bbbbbb');
  if (data.dense) layers.dense = points(THREE, data.dense, 1, '#999999');
  for (const obj of Object.values(layers)) scene.add(obj);

  const clouds = [];
  if (data.map) clouds.push(layers.map.geometry.attributes.position.array);
  if (data.dense) clouds.push(layers.dense.geometry.attributes.position.array);
  const ext = extent(trajArrays, clouds);
  const target = new THREE.Vector3(ext.centre[0], ext.centre[1], ext.centre[2]);
  const up = data.up ? new THREE.Vector3(data.up[0], data.up[1], data.up[2]) : new THREE.Vector3(0, -1, 0);
  let forward = data.forward ? new THREE.Vector3(data.forward[0], data.forward[1], data.forward[2]) : new THREE.Vector3(0, 0, 1);
  // Start behind and above the cameras, looking the way they looked.
  forward = forward.sub(up.clone().multiplyScalar(forward.dot(up)));
  if (forward.lengthSq() < 1e-6) forward = new THREE.Vector3(1, 0, 0).sub(up.clone().multiplyScalar(up.x));
  forward.normalize();
  const camera = new THREE.PerspectiveCamera(50, width / height, ext.radius / 1000, ext.radius * 200);
  camera.up.copy(up);
  camera.position.copy(target).addScaledVector(forward, -2.0 * ext.radius).addScaledVector(up, 1.2 * ext.radius);
  camera.lookAt(target);
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.target.copy(target);
  controls.update();

  const render = () => renderer.render(scene, camera);

  // Self-check: render the estimated trajectory alone and count the pixels it covered.
  for (const [name, obj] of Object.entries(layers)) obj.visible = name === 'estimate';
  render();
  const gl = renderer.getContext();
  const pixels = new Uint8Array(width * height * 4);
  gl.readPixels(0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, pixels);
  let drawn = 0;
  for (let i = 0; i < pixels.length; i += 4) {
    if (Math.abs(pixels[i] - 0x11) + Math.abs(pixels[i + 1] - 0x16) + Math.abs(pixels[i + 2] - 0x1c) > 30) ++drawn;
  }
  for (const obj of Object.values(layers)) obj.visible = true;
  render();

  controls.addEventListener('change', render);
  for (const box of document.querySelectorAll('.viewer-controls input[data-layer]')) {
    const obj = layers[box.dataset.layer];
    if (!obj) {
      box.disabled = true;
      box.checked = false;
      continue;
    }
    box.addEventListener('change', () => {
      obj.visible = box.checked;
      render();
    });
  }
  document.getElementById('point-size').addEventListener('input', (ev) => {
    const s = Number(ev.target.value);
    if (layers.map) layers.map.material.size = s;
    if (layers.dense) layers.dense.material.size = Math.max(1, s - 1);
    render();
  });
  new ResizeObserver(() => {
    const w = root.clientWidth;
    const h = root.clientHeight;
    if (w > 0 && h > 0) {
      renderer.setSize(w, h);
      camera.aspect = w / h;
      camera.updateProjectionMatrix();
      render();
    }
  }).observe(root);

  root.dataset.trajectoryPoints = String(layers.estimate.geometry.attributes.position.count);
  root.dataset.trajectoryPixels = String(drawn);
  root.dataset.viewerStatus = drawn > 0 ? 'ok' : 'error';
  if (drawn === 0) root.dataset.viewerError = 'the trajectory covered no pixel';
}

main().catch((e) => fail(String(e && e.message ? e.message : e)));
