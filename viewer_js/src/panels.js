// The small panels: a plot of one measure over the recording with a cursor at the current
// time, and the label timeline (one row per tier; click a label to go to its start).

export function drawPlot(canvas, times, values, f, title) {
  const ctx = canvas.getContext("2d");
  const w = canvas.width;
  const h = canvas.height;
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, w, h);
  const t0 = times[0];
  const t1 = times[times.length - 1];
  let lo = Infinity;
  let hi = -Infinity;
  for (const v of values) {
    if (Number.isFinite(v)) {
      lo = Math.min(lo, v);
      hi = Math.max(hi, v);
    }
  }
  ctx.fillStyle = "#222";
  ctx.font = "11px sans-serif";
  if (!Number.isFinite(lo)) {
    ctx.fillText(`${title}: not measured in this recording`, 4, 12);
    return;
  }
  if (hi - lo < 1e-6) hi = lo + 1;
  const pad = 0.08 * (hi - lo);
  const X = (t) => ((t - t0) / (t1 - t0 || 1)) * w;
  const Y = (v) => h - 4 - ((v - lo + pad) / (hi - lo + 2 * pad)) * (h - 18);
  ctx.strokeStyle = "#2a5db0";
  ctx.lineWidth = 1.2;
  ctx.beginPath();
  let started = false;
  for (let i = 0; i < values.length; i++) {
    if (!Number.isFinite(values[i])) {
      started = false;
      continue;
    }
    ctx[started ? "lineTo" : "moveTo"](X(times[i]), Y(values[i]));
    started = true;
  }
  ctx.stroke();
  ctx.strokeStyle = "#d11";
  ctx.beginPath();
  ctx.moveTo(X(times[f]), 0);
  ctx.lineTo(X(times[f]), h);
  ctx.stroke();
  const now = Number.isFinite(values[f]) ? values[f].toFixed(2) : "-";
  ctx.fillStyle = "#222";
  ctx.fillText(`${title}: ${now}   [${lo.toFixed(1)}, ${hi.toFixed(1)}]`, 4, 12);
}

export function buildTimeline(root, data, seek) {
  const tiers = data.labels || [];
  if (!tiers.length) {
    root.textContent = "no phone or word labels beside this recording";
    return null;
  }
  const t0 = data.times[0];
  const t1 = data.times[data.times.length - 1];
  const span = t1 - t0 || 1;
  const boxes = [];
  const cursors = [];
  for (const tier of tiers) {
    const row = document.createElement("div");
    row.className = "cassi-tier";
    row.title = tier.name;
    const name = document.createElement("span");
    name.className = "cassi-tier-name";
    name.textContent = tier.name;
    row.appendChild(name);
    const track = document.createElement("div");
    track.className = "cassi-track";
    row.appendChild(track);
    const cursor = document.createElement("div");
    cursor.className = "cassi-cursor";
    track.appendChild(cursor);
    cursors.push(cursor);
    for (const [start, end, text] of tier.segments) {
      const box = document.createElement("div");
      box.className = "cassi-label";
      const a = Math.max(start, t0);
      const b = Math.min(end, t1);
      if (b <= a) continue;
      box.style.left = `${(100 * (a - t0)) / span}%`;
      box.style.width = `${(100 * (b - a)) / span}%`;
      box.textContent = text;
      box.title = `${text}  ${start.toFixed(3)}-${end.toFixed(3)} s`;
      box.dataset.start = String(start);
      box.onclick = () => seek(start);
      track.appendChild(box);
      boxes.push([start, end, text, box]);
    }
    root.appendChild(row);
  }
  return {
    at(t) {
      const found = boxes.filter(([s, e]) => s <= t && t < e).map((b) => b[2]);
      return found.join(" / ");
    },
    mark(t) {
      for (const cursor of cursors) cursor.style.left = `${(100 * (t - t0)) / span}%`;
      for (const [s, e, , box] of boxes) box.classList.toggle("on", s <= t && t < e);
    },
  };
}
