// End-to-end test of the web viewer (ctest web.viewer): a server with tokens, a simulated
// warehouse drive (IMU + VLP-16 + wheels) streamed into a session with `hanzo-fusion stream`,
// and Debian's chromium (driven by playwright-core) loading GET / while the log streams. The
// page must list the session, show its live pose (with its time), trajectory, map points, sensor
// table, health timeline, position uncertainty, grid scale and overview; without a token it must
// say so, and a token in the URL must be dropped unused. Then a FusionMap with Gaussian splats
// (`hanzo-fusion run` with fusion.mapping.splats on the warehouse with its camera), uploaded
// and opened with ?map=ID, must be drawn by the splat renderer; the map's points coloured by
// semantic label must show a legend with floor and wall. The screenshots are kept:
// TEST_ARTIFACTS/viewer.png, viewer-labels.png, viewer-splats.png.
//
//   node tests/web/viewer_test.mjs --binary build/apps/hanzo-fusion --out build/test-artifacts
import { spawn, execFileSync } from 'node:child_process';
import { createRequire } from 'node:module';
import fs from 'node:fs';
import path from 'node:path';
import readline from 'node:readline';

const argument = (name, fallback) => {
  const index = process.argv.indexOf(name);
  return index > 0 ? process.argv[index + 1] : fallback;
};
const binary = path.resolve(argument('--binary', 'build/apps/hanzo-fusion'));
const out = path.resolve(argument('--out', 'build/test-artifacts'));
const chromiumPath = argument('--chromium', '/usr/bin/chromium');
const require = createRequire(new URL('../../web/package.json', import.meta.url));
const { chromium } = require('playwright-core');

const scratch = path.join(out, 'viewer-e2e');
fs.rmSync(scratch, { recursive: true, force: true });
fs.mkdirSync(scratch, { recursive: true });
const children = [];
const fail = (message) => {
  console.error(`web.viewer: FAILED: ${message}`);
  for (const child of children) child.kill('SIGKILL');
  process.exit(1);
};
const check = (condition, message) => { if (!condition) fail(message); };

// 1. The log: the warehouse scenario without its camera (the viewer shows LiDAR maps).
const scenario = fs.readFileSync('examples/scenarios/warehouse_robot.yaml', 'utf8').split('\n');
const trimmed = [];
let inCamera = false;
for (const line of scenario) {
  if (/^    camera_front:/.test(line)) { inCamera = true; continue; }
  if (inCamera && /^    \S/.test(line)) inCamera = false;
  if (inCamera && /^  \S/.test(line)) inCamera = false;
  if (!inCamera) trimmed.push(line);
}
fs.writeFileSync(path.join(scratch, 'warehouse.yaml'), trimmed.join('\n'));
execFileSync(binary, ['sim', path.join(scratch, 'warehouse.yaml'), '--out', path.join(scratch, 'sim'), '--duration', '14', '--no-foxglove'],
             { stdio: ['ignore', 'ignore', 'inherit'] });

// 2. The server, on free ports.
const token = 'viewer-test-token-0123456789';
fs.writeFileSync(path.join(scratch, 'tokens.yaml'), `tokens:
  - name: viewer-test
    organization: acme
    permissions: [fusion:session:write, fusion:session:read, fusion:map:read, fusion:map:write]
    token: "${token}"
`);
const server = spawn(binary, ['serve', '--tokens', path.join(scratch, 'tokens.yaml'), '--port', '0', '--grpc-port', '0', '--bind', '127.0.0.1',
                              '--data-dir', path.join(scratch, 'data'), '--json'], { stdio: ['ignore', 'pipe', 'inherit'] });
children.push(server);
const ready = await new Promise((resolve) => {
  const timer = setTimeout(() => resolve(null), 20000);
  readline.createInterface({ input: server.stdout }).once('line', (line) => { clearTimeout(timer); resolve(JSON.parse(line)); });
});
check(ready, 'the server did not start');
const base = `http://127.0.0.1:${ready.rest_port}`;

const browser = await chromium.launch({ executablePath: chromiumPath, args: ['--no-sandbox', '--enable-unsafe-swiftshader', '--use-angle=swiftshader'] });
const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
const pageErrors = [];
page.on('pageerror', (error) => pageErrors.push(error.message));

// 3. Without a token the page loads and asks for one.
await page.goto(`${base}/`);
await page.waitForFunction(() => document.getElementById('status').textContent === 'enter an API token', null, { timeout: 15000 })
  .catch(() => fail('without a token the page does not ask for one'));
// ... and stops polling until one is entered (no console full of 401s).
let unauthorized = 0;
page.on('response', (response) => { if (response.status() === 401) ++unauthorized; });
await new Promise((resolve) => setTimeout(resolve, 2000));
check(unauthorized === 0, `the page kept polling without a token: ${unauthorized} answers 401 in 2 s`);

// 4. A session streaming the log (1.5x real time) while the page watches it.
const simDir = path.join(scratch, 'sim');
const stream = spawn(binary, ['stream', path.join(simDir, 'sensors.mcap'), '--server', `127.0.0.1:${ready.grpc_port}`, '--rest', base,
                              '--config', path.join(simDir, 'fusion.yaml'), '--calib', path.join(simDir, 'calibration.yaml'),
                              '--token', token, '--rate', '1.5', '--name', 'warehouse patrol', '--json'],
                     { stdio: ['ignore', 'pipe', 'inherit'] });
children.push(stream);
let streamOutput = '';
stream.stdout.on('data', (chunk) => { streamOutput += chunk; });
const streamed = new Promise((resolve) => stream.on('exit', resolve));

// A token in the URL is removed from it unread (it would stay in browser history and server
// logs); the page's token field (kept in sessionStorage) is the way in.
await page.goto(`${base}/?token=${token}`);
check(!page.url().includes(token), `the token stayed in the URL: ${page.url()}`);
check(await page.evaluate(() => window.viewerState.token === ''), 'a token in the URL was used');
await page.fill('#token', token);
await page.click('#token-form button');
check(await page.evaluate(() => sessionStorage.getItem('hanzo-fusion-token')) === token, 'the token is not in sessionStorage');
check(await page.evaluate(() => localStorage.getItem('hanzo-fusion-token')) === null, 'the token went to localStorage');
await page.waitForFunction(() => {
  const s = window.viewerState;
  return s && s.sessions.length === 1 && s.poses > 5 && s.trajectoryPoints > 100 && s.mapPoints > 1000 && s.healthSamples > 5 &&
         s.sigmaPoints > 100 && s.fits > 0;
}, null, { timeout: 90000, polling: 500 }).catch(async () => {
  fail(`the page did not show the streaming session: ${JSON.stringify(await page.evaluate(() => window.viewerState))}`);
});
const live = await page.evaluate(() => ({ ...window.viewerState }));
const sessionText = await page.textContent('#sessions');
check(sessionText.includes('warehouse patrol'), `the session list shows '${sessionText}'`);
const sensorRows = await page.$$eval('#sensors tbody tr', (rows) => rows.map((row) => row.firstChild.textContent));
check(['imu', 'lidar', 'wheels'].every((name) => sensorRows.includes(name)), `sensor table: ${sensorRows}`);
// The latest pose's time, the grid's scale, the overview on demand.
const poseRows = await page.$$eval('#pose tr', (rows) => rows.map((row) => row.textContent));
check(poseRows.some((text) => /^time20\d\d-\d\d-\d\d \d\d:\d\d:\d\d\.\d{3} UTC$/.test(text)), `pose table: ${poseRows}`);
check(/^grid \d+(\.\d+)? m$/.test(await page.textContent('#scale')), `grid scale: ${await page.textContent('#scale')}`);
const fitsBefore = live.fits;
await page.click('#fit');
check(await page.evaluate((before) => window.viewerState.fits === before + 1, fitsBefore), 'the overview button did nothing');
check(!(await page.isChecked('#follow')), 'the overview left "follow the robot" on');
fs.mkdirSync(out, { recursive: true });
await page.screenshot({ path: path.join(out, 'viewer.png') });

// 5. The stream finishes; the page keeps up.
const code = await streamed;
check(code === 0, `hanzo-fusion stream exited ${code}`);
const summary = JSON.parse(streamOutput);
await page.waitForFunction((stored) => window.viewerState.trajectoryPoints >= stored, summary.session.stored_poses, { timeout: 15000 })
  .catch(() => fail('the trajectory did not catch up with the stored poses'));
check(pageErrors.length === 0, `page errors: ${pageErrors.join('; ')}`);
check(fs.statSync(path.join(out, 'viewer.png')).size > 10000, 'the screenshot is empty');

// The map's points by semantic label: the legend names floor and wall, their points add up to the map's.
await page.selectOption('#colour', 'labels');
await page.waitForFunction(() => {
  const names = window.viewerState.legend.map((entry) => entry.name);
  return names.includes('floor') && names.includes('wall');
}, null, { timeout: 15000, polling: 500 }).catch(async () => fail(`no label legend: ${JSON.stringify(await page.evaluate(() => ({ legend: window.viewerState.legend, error: window.viewerState.lastError, version: window.viewerState.mapVersion, colour: window.viewerState.colour })))}`));
const labelled = await page.evaluate(() => ({ legend: window.viewerState.legend, points: window.viewerState.mapPoints }));
check(labelled.legend.reduce((sum, entry) => sum + entry.points, 0) === labelled.points, `label legend ${JSON.stringify(labelled)}`);
const legendText = await page.textContent('#legend');
check(/floor \(\d+\)/.test(legendText) && /wall \(\d+\)/.test(legendText), `legend shown: ${legendText}`);
await page.screenshot({ path: path.join(out, 'viewer-labels.png') });
// No segmentation on this LiDAR-only drive: the legend says so, the points stay shown.
await page.selectOption('#colour', 'classes');
await page.waitForFunction(() => window.viewerState.legend.some((entry) => entry.name === "the map's points have no classes"), null,
                           { timeout: 15000, polling: 500 }).catch(() => fail('selecting classes on a map without them did not say so'));
await page.selectOption('#colour', 'height');
check(pageErrors.length === 0, `page errors: ${pageErrors.join('; ')}`);

// 6. A FusionMap with Gaussian splats: 12 s of the warehouse with its camera, mapped with splats.
const splatSim = path.join(scratch, 'splat-sim');
execFileSync(binary, ['sim', 'examples/scenarios/warehouse_robot.yaml', '--out', splatSim, '--duration', '12', '--no-foxglove'], { stdio: ['ignore', 'ignore', 'inherit'] });
const splatConfig = fs.readFileSync(path.join(splatSim, 'fusion.yaml'), 'utf8').replace(/^fusion:\n/m, 'fusion:\n  mapping:\n    splats: {image_width: 80}\n');
fs.writeFileSync(path.join(splatSim, 'fusion-splats.yaml'), splatConfig);
execFileSync(binary, ['run', '--config', path.join(splatSim, 'fusion-splats.yaml'), '--calibration', path.join(splatSim, 'calibration.yaml'),
                      '--log', path.join(splatSim, 'sensors.mcap'), '--out', path.join(splatSim, 'run'), '--json'], { stdio: ['ignore', 'ignore', 'inherit'] });
const upload = await fetch(`${base}/v1/maps?name=warehouse-splats`, { method: 'POST', headers: { Authorization: `Bearer ${token}` },
                                                                       body: fs.readFileSync(path.join(splatSim, 'run', 'map.fmap')) });
check(upload.status === 201, `uploading the map with splats: HTTP ${upload.status}`);
const { map_id: mapId } = await upload.json();
const splatPly = await fetch(`${base}/v1/maps/${mapId}?format=splats`, { headers: { Authorization: `Bearer ${token}` } });
check(splatPly.status === 200 && (await splatPly.text()).startsWith('ply\n'), `GET /v1/maps/${mapId}?format=splats: HTTP ${splatPly.status}`);
await page.goto(`${base}/?map=${mapId}`);
await page.waitForFunction(() => window.viewerState.storedMapShown && window.viewerState.splats > 1000, null, { timeout: 60000, polling: 500 })
  .catch(async () => fail(`the page did not show the map's splats: ${JSON.stringify(await page.evaluate(() => window.viewerState))}`));
// The pixels the splats draw: points hidden, the share of the view that differs from the
// background with the splats shown, less that without them (the grid).
const drawnShare = () => page.evaluate(() => {
  const source = document.querySelector('#view canvas');
  const copy = document.createElement('canvas');
  copy.width = source.width;
  copy.height = source.height;
  const context = copy.getContext('2d');
  context.drawImage(source, 0, 0);
  const { data } = context.getImageData(0, 0, copy.width, copy.height);
  let drawn = 0;
  for (let i = 0; i < data.length; i += 4) {
    if (Math.abs(data[i] - 0x10) + Math.abs(data[i + 1] - 0x14) + Math.abs(data[i + 2] - 0x18) > 30) ++drawn;
  }
  return drawn / (data.length / 4);
});
const settle = () => new Promise((resolve) => setTimeout(resolve, 1500));
// Spark sorts and draws on its own schedule: poll (at most 30 s) until `done(share)`.
const drawnUntil = async (done) => {
  let share = await drawnShare();
  for (let tries = 0; tries < 20 && !done(share); ++tries) {
    await settle();
    share = await drawnShare();
  }
  return share;
};
// Points and grid hidden: what differs from the background is the splats.
await page.click('#show-points');
await page.click('#show-grid');
const covered = await drawnUntil((share) => share > 0.015);
await page.screenshot({ path: path.join(out, 'viewer-splats.png') });
check(covered > 0.015, `the splats cover ${(100 * covered).toFixed(1)} % of the view`);  // 12 s of the warehouse seen from above: about 3 %
// The splats switch off and on again.
await page.click('#show-splats');
const hidden = await drawnUntil((share) => share < 0.001);
check(hidden < 0.001, `with the splats switched off ${(100 * hidden).toFixed(1)} % of the view is drawn`);
await page.click('#show-splats');
const shownAgain = await drawnUntil((share) => share > 0.015);
check(shownAgain > 0.015, `switched on again the splats cover ${(100 * shownAgain).toFixed(1)} % of the view`);
const splatsShown = await page.evaluate(() => window.viewerState.splats);
check(pageErrors.length === 0, `page errors: ${pageErrors.join('; ')}`);
await browser.close();
server.kill('SIGTERM');
await new Promise((resolve) => server.on('exit', resolve));
console.log(`web.viewer: ok: while streaming ${live.poses} live poses, ${live.trajectoryPoints} trajectory poses, ${live.mapPoints} map points shown; ` +
            `${summary.messages_sent} messages streamed; screenshot ${path.join(out, 'viewer.png')}; a stored map's ${splatsShown} splats cover ` +
            `${(100 * covered).toFixed(1)} % of the view (${path.join(out, 'viewer-splats.png')})`);
