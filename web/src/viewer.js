// The server's web viewer (GET /): the organization's sessions, the selected session's live pose,
// trajectory, map points, Gaussian splats (fusion.mapping.splats; drawn by Spark, a three.js
// splat renderer) and sensor health, in 3D, with an overview (zoom to fit), a grid with
// its scale, the time of the latest pose, a per-sensor health timeline and the position
// uncertainty over time. Talks to the REST API of the server that serves it (docs/server.md)
// with the token typed into the page, kept in sessionStorage (never in the URL: a `?token=`
// there is removed unread, as it lands in browser history and server logs). `?session=ID`
// selects a session, `?map=ID` shows a stored FusionMap's points and splats instead. The points
// are coloured by height, by semantic label (floor, wall, obstacle, traversable: ?format=labels)
// or by segmentation class (?format=classes), with a legend. Polls: sessions every second, the
// pose 5 times a second, new trajectory poses every second, the map when its version changes,
// the splats at most every 5 s while they train.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import { SparkRenderer, SplatMesh } from '@sparkjsdev/spark';
import { HealthTimeline, SigmaChart } from './timelines.js';

const query = new URLSearchParams(location.search);
const tokenInUrl = query.has('token');
if (tokenInUrl) {
  query.delete('token');
  const rest = query.toString();
  history.replaceState(null, '', `${location.pathname}${rest ? `?${rest}` : ''}`);
}

const state = {
  token: sessionStorage.getItem('hanzo-fusion-token') || '',
  needsToken: false,      // a 401 came back: polling waits for a token
  selected: query.get('session') || null,
  storedMap: query.get('map') || null,  // a stored FusionMap shown instead of a session
  storedMapShown: false,
  sessions: [],
  poses: 0,               // poses received for the selected session
  latestPoseNs: null,
  trajectoryPoints: 0,
  trajectoryAfter: null,  // next_after of the trajectory paging
  mapVersion: -1,
  mapPoints: 0,
  colour: 'height',       // the map points' colouring: height, labels or classes
  mapColour: 'height',    // the colouring of the map points shown
  legend: [],             // [{ name, colour: [r, g, b], points }] of the labels / classes shown
  splats: 0,              // Gaussians drawn
  splatIterations: -1,    // the session's training steps when they were fetched
  splatFetchedAt: 0,      // ms (performance.now())
  gridSpacing: 2,         // m between grid lines
  healthSamples: 0,       // poses in the health timeline
  sigmaPoints: 0,         // poses in the uncertainty chart
  fits: 0,                // overviews shown
  errors: 0,
  lastError: '',
};
window.viewerState = state;  // read by the end-to-end test

const $ = (id) => document.getElementById(id);

function setStatus(text, kind = 'ok') {
  $('status').textContent = text;
  $('status').dataset.state = kind;
}

async function api(path, { binary = false } = {}) {
  const headers = state.token ? { Authorization: `Bearer ${state.token}` } : {};
  const response = await fetch(path, { headers });
  if (!response.ok) {
    let message = `HTTP ${response.status}`;
    try { message = (await response.json()).error.message; } catch (_) { /* not JSON */ }
    const error = new Error(message);
    error.status = response.status;
    throw error;
  }
  return binary ? response.arrayBuffer() : response.json();
}

// --- 3D scene (world frame: x east, y north, z up) ---
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
$('view').appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x101418);
const camera = new THREE.PerspectiveCamera(60, 1, 0.1, 5000);
camera.up.set(0, 0, 1);
camera.position.set(-20, -20, 25);
const controls = new OrbitControls(camera, renderer.domElement);
controls.target.set(0, 0, 0);
scene.add(new THREE.AmbientLight(0xffffff, 1.0));
let grid = null;
// A grid covering `box` (or 200 m around the origin) with lines every 1, 2 or 5 x 10^k m, about
// 20 across; the overlay names the spacing.
function setGrid(box) {
  const size = box && !box.isEmpty() ? Math.max(box.max.x - box.min.x, box.max.y - box.min.y, 10) : 200;
  const step = 10 ** Math.floor(Math.log10(size / 20));
  const spacing = [1, 2, 5, 10].map((m) => m * step).find((s) => size / s <= 25);
  const cells = Math.ceil(size / spacing) + 2;
  const center = box && !box.isEmpty() ? box.getCenter(new THREE.Vector3()) : new THREE.Vector3();
  if (grid) scene.remove(grid);
  grid = new THREE.GridHelper(cells * spacing, cells, 0x30363d, 0x1f252c);
  grid.rotation.x = Math.PI / 2;
  grid.position.set(Math.round(center.x / spacing) * spacing, Math.round(center.y / spacing) * spacing, box && !box.isEmpty() ? box.min.z : 0);
  grid.visible = $('show-grid').checked;
  scene.add(grid);
  state.gridSpacing = spacing;
  $('scale').textContent = `grid ${spacing >= 1 ? spacing : spacing.toFixed(2)} m`;
}
setGrid(null);

const robot = new THREE.AxesHelper(2.0);
robot.visible = false;
scene.add(robot);

const maxTrajectory = 200000;
const trajectoryPositions = new Float32Array(maxTrajectory * 3);
const trajectoryGeometry = new THREE.BufferGeometry();
trajectoryGeometry.setAttribute('position', new THREE.BufferAttribute(trajectoryPositions, 3));
trajectoryGeometry.setDrawRange(0, 0);
scene.add(new THREE.Line(trajectoryGeometry, new THREE.LineBasicMaterial({ color: 0xffa657 })));

const health = new HealthTimeline($('health'));
const sigma = new SigmaChart($('sigma'));

const mapGeometry = new THREE.BufferGeometry();
const map = new THREE.Points(mapGeometry, new THREE.PointsMaterial({ size: 0.08, vertexColors: true }));
scene.add(map);

// Gaussian splats (the map's splat layer, as the PLY of GET .../map?format=splats), world frame.
scene.add(new SparkRenderer({ renderer }));
let splatMesh = null;
async function showSplats(bytes) {
  const header = new TextDecoder().decode(new Uint8Array(bytes, 0, Math.min(bytes.byteLength, 4096)));
  const count = Number((header.match(/^element vertex (\d+)$/m) || [, 0])[1]);
  const mesh = new SplatMesh({ fileBytes: bytes, fileType: 'ply' });
  await mesh.initialized;
  if (splatMesh) {
    scene.remove(splatMesh);
    splatMesh.dispose();
  }
  splatMesh = mesh;
  placeSplats();
  state.splats = count;
}
// Shown and hidden by joining and leaving the scene (Spark redraws when its set of splat meshes
// changes; a visibility flag alone waits for the next camera motion).
function placeSplats() {
  if (!splatMesh) return;
  if ($('show-splats').checked) scene.add(splatMesh);
  else scene.remove(splatMesh);
  splatMesh.needsUpdate = true;
}
$('show-splats').addEventListener('change', placeSplats);
$('show-points').addEventListener('change', () => { map.visible = $('show-points').checked; });
$('show-grid').addEventListener('change', () => { grid.visible = $('show-grid').checked; });

// The overview: the camera looks down at the whole map and trajectory.
function fitView() {
  const box = new THREE.Box3();
  for (const geometry of [mapGeometry, trajectoryGeometry]) {
    const positions = geometry.getAttribute('position');
    const count = geometry === trajectoryGeometry ? state.trajectoryPoints : positions ? positions.count : 0;
    for (let i = 0; i < count; ++i) box.expandByPoint(new THREE.Vector3().fromBufferAttribute(positions, i));
  }
  if (robot.visible) box.expandByPoint(robot.position);
  if (box.isEmpty()) return;
  setGrid(box);
  const center = box.getCenter(new THREE.Vector3());
  const radius = Math.max(5, box.getSize(new THREE.Vector3()).length() / 2);
  const distance = radius / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2)) * (camera.aspect < 1 ? 1 / camera.aspect : 1);
  $('follow').checked = false;
  controls.target.copy(center);
  camera.position.set(center.x, center.y - distance * 0.25, center.z + distance);
  camera.far = Math.max(5000, distance * 4);
  camera.updateProjectionMatrix();
  ++state.fits;
}

function resize() {
  const { clientWidth: width, clientHeight: height } = $('view');
  renderer.setSize(width, height);
  camera.aspect = width / Math.max(1, height);
  camera.updateProjectionMatrix();
}
window.addEventListener('resize', resize);
resize();
(function animate() {
  requestAnimationFrame(animate);
  controls.update();
  renderer.render(scene, camera);
})();

// The text header of a binary point file up to and including `marker`, and where the data starts.
function readHeader(buffer, marker, kind) {
  const bytes = new Uint8Array(buffer);
  let header = '';
  let offset = 0;
  while (offset < bytes.length && !header.endsWith(marker)) header += String.fromCharCode(bytes[offset++]);
  if (!header.endsWith(marker)) throw new Error(`map: not a binary ${kind}`);
  return { header, offset };
}

// --- PCD (binary, as GET /map?format=pcd writes it) ---
function parsePcd(buffer) {
  const { header, offset } = readHeader(buffer, 'DATA binary\n', 'PCD');
  const field = (name) => (header.match(new RegExp(`^${name} (.*)$`, 'm')) || [, ''])[1].trim().split(/\s+/);
  const names = field('FIELDS');
  const sizes = field('SIZE').map(Number);
  const counts = field('COUNT').map(Number);
  const points = Number(field('POINTS')[0]);
  const offsets = {};
  let stride = 0;
  names.forEach((name, i) => { offsets[name] = stride; stride += sizes[i] * (counts[i] || 1); });
  const view = new DataView(buffer, offset);
  const positions = new Float32Array(points * 3);
  for (let i = 0; i < points; ++i) {
    for (let axis = 0; axis < 3; ++axis) positions[3 * i + axis] = view.getFloat32(i * stride + offsets['xyz'[axis]], true);
  }
  return positions;
}

// --- PLY of coloured points (binary little endian, as ?format=labels / classes write it):
// positions, colours (0..1) and the legend: per label / class value its name, colour and count.
const PLY_SIZES = { char: 1, uchar: 1, short: 2, ushort: 2, int: 4, uint: 4, float: 4, double: 8 };
const LABEL_NAMES = ['unknown', 'floor', 'wall', 'obstacle', 'traversable'];
function parseColouredPly(buffer) {
  const { header, offset } = readHeader(buffer, 'end_header\n', 'PLY');
  if (!header.startsWith('ply\nformat binary_little_endian')) throw new Error('map: not a little-endian binary PLY');
  const points = Number((header.match(/^element vertex (\d+)$/m) || [, '0'])[1]);
  const offsets = {}, types = {};
  let stride = 0;
  for (const [, type, name] of header.matchAll(/^property (\w+) (\w+)$/gm)) {
    offsets[name] = stride;
    types[name] = type;
    stride += PLY_SIZES[type];
  }
  const names = {};
  for (const [, id, name] of header.matchAll(/^comment class (\d+) (.+)$/gm)) names[id] = name;
  const key = 'label' in offsets ? 'label' : 'class';
  const view = new DataView(buffer, offset);
  const positions = new Float32Array(points * 3), colors = new Float32Array(points * 3);
  const legend = new Map();
  for (let i = 0; i < points; ++i) {
    const at = i * stride;
    for (let axis = 0; axis < 3; ++axis) positions[3 * i + axis] = view.getFloat32(at + offsets['xyz'[axis]], true);
    const rgb = ['red', 'green', 'blue'].map((channel) => view.getUint8(at + offsets[channel]));
    colors.set(rgb.map((value) => value / 255), 3 * i);
    const value = types[key] === 'ushort' ? view.getUint16(at + offsets[key], true) : view.getUint8(at + offsets[key]);
    if (!legend.has(value)) {
      const name = key === 'label' ? LABEL_NAMES[value] ?? `label ${value}` : value === 65535 ? 'no class' : names[value] ?? `class ${value}`;
      legend.set(value, { name, colour: rgb, points: 0 });
    }
    ++legend.get(value).points;
  }
  return { positions, colors, legend: [...legend.values()].sort((a, b) => b.points - a.points) };
}

function showLegend() {
  $('legend').replaceChildren(...state.legend.map(({ name, colour, points }) => {
    const item = document.createElement('li');
    const swatch = document.createElement('span');
    swatch.className = 'swatch';
    swatch.style.background = `rgb(${colour.join(',')})`;
    item.append(swatch, `${name} (${points})`);
    return item;
  }));
}

// The map's points for the chosen colouring: a PCD coloured by height, or the labels' / classes' PLY.
async function fetchMap(path) {
  const colour = state.colour;
  if (colour === 'height') {
    showMap(parsePcd(await api(`${path}?format=pcd`, { binary: true })));
    state.legend = [];
  } else {
    try {
      const { positions, colors, legend } = parseColouredPly(await api(`${path}?format=${colour}`, { binary: true }));
      state.legend = legend;
      showMap(positions, colors);
    } catch (error) {
      if (error.status !== 404) throw error;
      state.legend = [{ name: `the map's points have no ${colour}`, colour: [128, 128, 128], points: 0 }];
      showMap(parsePcd(await api(`${path}?format=pcd`, { binary: true })));
    }
  }
  state.mapColour = colour;
  showLegend();
}

function heightColours(positions) {
  let low = Infinity, high = -Infinity;
  for (let i = 2; i < positions.length; i += 3) { low = Math.min(low, positions[i]); high = Math.max(high, positions[i]); }
  const colors = new Float32Array(positions.length);
  const color = new THREE.Color();
  for (let i = 0; i < positions.length / 3; ++i) {
    const t = high > low ? (positions[3 * i + 2] - low) / (high - low) : 0.5;
    color.setHSL(0.66 * (1 - t), 0.8, 0.55);
    colors.set([color.r, color.g, color.b], 3 * i);
  }
  return colors;
}

function showMap(positions, colors = heightColours(positions)) {
  mapGeometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
  mapGeometry.setAttribute('color', new THREE.BufferAttribute(colors, 3));
  mapGeometry.computeBoundingSphere();
  state.mapPoints = positions.length / 3;
}

function resetSessionView() {
  state.poses = 0;
  state.trajectoryPoints = 0;
  state.trajectoryAfter = null;
  state.mapVersion = -1;
  state.mapPoints = 0;
  trajectoryGeometry.setDrawRange(0, 0);
  mapGeometry.deleteAttribute('position');
  mapGeometry.deleteAttribute('color');
  if (splatMesh) {
    scene.remove(splatMesh);
    splatMesh.dispose();
    splatMesh = null;
  }
  state.splats = 0;
  state.splatIterations = -1;
  robot.visible = false;
  state.latestPoseNs = null;
  health.clear();
  sigma.clear();
}

// --- side panel ---
function row(cells, tag = 'td') {
  const tr = document.createElement('tr');
  for (const cell of cells) {
    const element = document.createElement(tag);
    element.textContent = cell;
    tr.appendChild(element);
  }
  return tr;
}

function renderSessions() {
  const list = $('sessions');
  list.replaceChildren();
  for (const session of state.sessions) {
    const item = document.createElement('li');
    item.dataset.id = session.id;
    item.textContent = session.name;
    const badge = document.createElement('span');
    badge.className = `state ${session.tracking_state}`;
    badge.textContent = session.status === 'ended' ? 'ENDED' : session.tracking_state;
    item.appendChild(badge);
    if (session.id === state.selected) item.classList.add('selected');
    item.addEventListener('click', () => { state.selected = session.id; resetSessionView(); renderSessions(); refreshSession(); });
    list.appendChild(item);
  }
}

function renderDetails(session) {
  $('details').hidden = false;
  $('session-name').textContent = `${session.name} (${session.status})`;
  const body = $('sensors').querySelector('tbody');
  body.replaceChildren();
  for (const sensor of session.sensors) {
    const rejected = Object.values(sensor.rejected || {}).reduce((a, b) => a + b, 0);
    // Received but never fused (a modality the configured frontend does not use) is no outage.
    const notFused = !sensor.timed_out && sensor.fused === 0 && sensor.received > 0 && (sensor.rejected || {}).not_fused > 0;
    const tr = row([sensor.name, sensor.received, sensor.fused, rejected, sensor.timed_out ? 'silent' : notFused ? 'not fused' : '']);
    tr.title = Object.entries(sensor.rejected || {}).map(([reason, count]) => `${reason}: ${count}`).join('\n');
    if (sensor.timed_out) tr.classList.add('timed-out');
    body.appendChild(tr);
  }
  const mapping = session.mapping || {};
  $('mapping').replaceChildren(
    row(['sweeps registered', `${mapping.scans_registered ?? 0} / ${mapping.scans_received ?? 0}`]),
    row(['degenerate / weather', `${mapping.degenerate_scans ?? 0} / ${mapping.weather_degraded_scans ?? 0}`]),
    row(['map keyframes', mapping.map_keyframes ?? 0]),
    row(['loop closures', (mapping.loop_closures ?? 0) + (mapping.manual_loop_closures ?? 0)]),
    row(['map points', state.mapPoints]),
    row(['splats', `${state.splats} drawn; ${mapping.splat_gaussians ?? 0} Gaussians, ${mapping.splat_views ?? 0} views, ${mapping.splat_iterations ?? 0} steps`]),
  );
}

function renderPose(pose) {
  const [x, y, z] = pose.position;
  const [w, qx, qy, qz] = pose.orientation_wxyz;
  robot.position.set(x, y, z);
  robot.quaternion.set(qx, qy, qz, w);
  robot.visible = true;
  if ($('follow').checked) {
    const shift = new THREE.Vector3(x, y, z).sub(controls.target);
    controls.target.add(shift);
    camera.position.add(shift);
  }
  const speed = Math.hypot(...pose.velocity);
  const time = new Date(Number(pose.timestamp_ns) / 1e6);
  $('pose').replaceChildren(
    row(['time', `${time.toISOString().replace('T', ' ').replace('Z', ' UTC')}`]),
    row(['state', `${pose.state} (${pose.active_sensors.join(', ')})`]),
    row(['position', pose.position.map((v) => v.toFixed(2)).join(', ')]),
    row(['speed', `${speed.toFixed(2)} m/s`]),
  );
}

// --- polling ---
async function refreshSessions() {
  const { sessions } = await api('/v1/sessions');
  state.sessions = sessions;
  if (!state.selected && sessions.length) state.selected = sessions[sessions.length - 1].id;
  renderSessions();
}

async function refreshPose() {
  if (!state.selected) return;
  try {
    const pose = await api(`/v1/sessions/${state.selected}/pose`);
    renderPose(pose);
    ++state.poses;
    state.latestPoseNs = pose.timestamp_ns;
    health.add(pose.timestamp_ns, pose.sensor_health);
    health.draw();
    state.healthSamples = health.samples.length;
  } catch (error) {
    if (error.status !== 404) throw error;  // no pose yet
  }
}

async function refreshTrajectory() {
  if (!state.selected) return;
  const after = state.trajectoryAfter === null ? '' : `&after=${state.trajectoryAfter}`;
  const page = await api(`/v1/sessions/${state.selected}/trajectory?limit=10000${after}`);
  for (const pose of page.poses) {
    if (state.trajectoryPoints >= maxTrajectory) break;
    trajectoryPositions.set(pose.position, 3 * state.trajectoryPoints++);
    state.trajectoryAfter = pose.timestamp_ns;
    sigma.add(pose.timestamp_ns, pose.covariance);
  }
  if (page.poses.length) sigma.draw();
  state.sigmaPoints = sigma.points.length;
  // The first time there is something to see: the overview.
  if (state.fits === 0 && state.trajectoryPoints > 1) fitView();
  trajectoryGeometry.attributes.position.needsUpdate = true;
  trajectoryGeometry.setDrawRange(0, state.trajectoryPoints);
  trajectoryGeometry.computeBoundingSphere();
}

async function refreshSession() {
  if (!state.selected) return;
  const session = await api(`/v1/sessions/${state.selected}`);
  const version = session.mapping ? session.mapping.map_version : 0;
  if (version > 0 && (version !== state.mapVersion || state.colour !== state.mapColour)) {
    try {
      await fetchMap(`/v1/sessions/${state.selected}/map`);
      state.mapVersion = version;
    } catch (error) {
      if (error.status !== 404 && error.status !== 403) throw error;  // no map, or no map:read
    }
  }
  const mapping = session.mapping || {};
  const training = mapping.splat_iterations ?? 0;
  if ((mapping.splat_gaussians ?? 0) > 0 && training !== state.splatIterations && performance.now() - state.splatFetchedAt > 5000) {
    state.splatFetchedAt = performance.now();
    try {
      await showSplats(await api(`/v1/sessions/${state.selected}/map?format=splats`, { binary: true }));
      state.splatIterations = training;
    } catch (error) {
      if (error.status !== 404 && error.status !== 403) throw error;
    }
  }
  renderDetails(session);
}

// A stored FusionMap (?map=ID): its points and splats, once.
async function showStoredMap() {
  if (state.storedMapShown) return;
  const path = `/v1/maps/${encodeURIComponent(state.storedMap)}`;
  const optional = async (format, show) => {
    try {
      await show(await api(`${path}?format=${format}`, { binary: true }));
    } catch (error) {
      if (error.status !== 404) throw error;  // a map without that layer
    }
  };
  await fetchMap(path).catch((error) => { if (error.status !== 404) throw error; });  // a map without points
  await optional('splats', showSplats);
  state.storedMapShown = true;
  fitView();
}

function every(milliseconds, task) {
  let running = false;
  const tick = async () => {
    // Until a token is entered a server with auth answers 401 to everything: wait for it.
    if (running || state.needsToken) return;
    running = true;
    try {
      await task();
      if (state.storedMap) setStatus(`map ${state.storedMap}: ${state.mapPoints} points, ${state.splats} splats`);
      else if (state.sessions.length) setStatus(`${state.sessions.length} session(s); ${state.trajectoryPoints} poses, ${state.mapPoints} map points, ${state.splats} splats`);
      else setStatus('no sessions yet');
    } catch (error) {
      ++state.errors;
      state.lastError = error.message;
      if (error.status === 401) state.needsToken = true;
      setStatus(error.status === 401 ? 'enter an API token' : error.message, 'error');
    } finally {
      running = false;
    }
  };
  tick();
  setInterval(tick, milliseconds);
}

$('token').value = state.token;
$('token-form').addEventListener('submit', (event) => {
  event.preventDefault();
  state.token = $('token').value.trim();
  state.needsToken = false;
  sessionStorage.setItem('hanzo-fusion-token', state.token);
});
$('fit').addEventListener('click', fitView);
$('colour').addEventListener('change', () => {
  state.colour = $('colour').value;  // a session's map is fetched again by its next refresh
  if (state.storedMap) fetchMap(`/v1/maps/${encodeURIComponent(state.storedMap)}`).catch((error) => setStatus(error.message, 'error'));
});
if (tokenInUrl) setStatus('a token in the URL is not used (it would stay in browser history): enter it above', 'error');
if (state.storedMap) {
  every(2000, showStoredMap);
} else {
  every(1000, refreshSessions);
  every(200, refreshPose);
  every(1000, refreshTrajectory);
  every(1000, refreshSession);
}
