// The side panel's charts over time, drawn on 2D canvases: each sensor's health (ok, degraded,
// lost: one row per sensor, a coloured bar per sample) and the position's standard deviation
// (m, the square root of the trace of the pose covariance's position block).

const healthColours = { ok: '#238636', degraded: '#d29922', lost: '#da3633' };

function fitCanvas(canvas) {
  const ratio = window.devicePixelRatio || 1;
  const width = canvas.clientWidth, height = canvas.clientHeight;
  if (canvas.width !== width * ratio || canvas.height !== height * ratio) {
    canvas.width = width * ratio;
    canvas.height = height * ratio;
  }
  const context = canvas.getContext('2d');
  context.setTransform(ratio, 0, 0, ratio, 0, 0);
  context.clearRect(0, 0, width, height);
  context.font = '10px system-ui, sans-serif';
  return { context, width, height };
}

const seconds = (timeNs) => Number(timeNs) / 1e9;

// Samples of {time_s, health: {sensor: state}}, oldest first, at most `capacity`.
export class HealthTimeline {
  constructor(canvas, capacity = 3000) {
    this.canvas = canvas;
    this.capacity = capacity;
    this.samples = [];
  }

  clear() { this.samples = []; this.draw(); }

  add(timestampNs, sensorHealth) {
    const time = seconds(timestampNs);
    if (this.samples.length && time <= this.samples[this.samples.length - 1].time) return;  // the same pose again
    const health = {};
    for (const entry of sensorHealth || []) health[entry.sensor] = entry.state;
    this.samples.push({ time, health });
    if (this.samples.length > this.capacity) this.samples.shift();
  }

  draw() {
    const { context, width, height } = fitCanvas(this.canvas);
    const sensors = [...new Set(this.samples.flatMap((sample) => Object.keys(sample.health)))].sort();
    if (!sensors.length || this.samples.length < 2) {
      context.fillStyle = '#9fb0c0';
      context.fillText('no sensor health yet', 4, 12);
      return;
    }
    const label = 56, rowHeight = Math.min(14, (height - 12) / sensors.length);
    const first = this.samples[0].time, last = this.samples[this.samples.length - 1].time;
    const x = (time) => label + (width - label - 2) * (time - first) / Math.max(1e-9, last - first);
    sensors.forEach((sensor, row) => {
      const y = row * rowHeight;
      context.fillStyle = '#9fb0c0';
      context.fillText(sensor.slice(0, 9), 2, y + rowHeight - 3);
      for (let i = 0; i + 1 < this.samples.length; ++i) {
        const state = this.samples[i].health[sensor];
        if (!state) continue;
        context.fillStyle = healthColours[state] || '#30363d';
        context.fillRect(x(this.samples[i].time), y + 1, Math.max(1, x(this.samples[i + 1].time) - x(this.samples[i].time)), rowHeight - 2);
      }
    });
    context.fillStyle = '#9fb0c0';
    context.fillText(`last ${(last - first).toFixed(0)} s`, label, height - 2);
  }
}

// Points {time_s, sigma_m}, oldest first; every other point is dropped when full, so the chart
// covers the whole session at a coarser step.
export class SigmaChart {
  constructor(canvas, capacity = 4000) {
    this.canvas = canvas;
    this.capacity = capacity;
    this.points = [];
  }

  clear() { this.points = []; this.draw(); }

  add(timestampNs, covariance) {
    if (!covariance || covariance.length !== 36) return;
    const sigma = Math.sqrt(Math.max(0, covariance[0] + covariance[7] + covariance[14]));
    if (!Number.isFinite(sigma)) return;
    this.points.push({ time: seconds(timestampNs), sigma });
    if (this.points.length > this.capacity) this.points = this.points.filter((_, i) => i % 2 === 0);
  }

  draw() {
    const { context, width, height } = fitCanvas(this.canvas);
    if (this.points.length < 2) {
      context.fillStyle = '#9fb0c0';
      context.fillText('no covariance yet', 4, 12);
      return;
    }
    const first = this.points[0].time, last = this.points[this.points.length - 1].time;
    const top = Math.max(...this.points.map((p) => p.sigma)) * 1.1 || 1;
    const x = (time) => 2 + (width - 4) * (time - first) / Math.max(1e-9, last - first);
    const y = (sigma) => height - 12 - (height - 16) * sigma / top;
    context.strokeStyle = '#58a6ff';
    context.beginPath();
    this.points.forEach((p, i) => (i ? context.lineTo(x(p.time), y(p.sigma)) : context.moveTo(x(p.time), y(p.sigma))));
    context.stroke();
    context.fillStyle = '#9fb0c0';
    const latest = this.points[this.points.length - 1].sigma;
    context.fillText(`now ${latest.toFixed(3)} m, max ${(top / 1.1).toFixed(3)} m over ${(last - first).toFixed(0)} s`, 2, height - 2);
  }
}
