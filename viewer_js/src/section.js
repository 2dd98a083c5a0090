// The midsagittal section of the current frame on a 2D canvas: every part's triangles cut
// by the plane z = 0 (model frame) drawn as contours, as on an X-ray tracing, with the
// subject's palate and pharyngeal wall traces, the measured pellets with their trails (red)
// and the model's pellet sites (green). Front of the face to the right.

export class Section {
  constructor(canvas, data) {
    this.canvas = canvas;
    this.data = data;
    this.ctx = canvas.getContext("2d");
    this.box = data.section.box; // [xmin, ymin, xmax, ymax] mm, the vocal tract's area
  }

  _transform() {
    const [x0, y0, x1, y1] = this.box;
    const w = this.canvas.width;
    const h = this.canvas.height;
    const s = Math.min(w / (x1 - x0), h / (y1 - y0));
    const ox = (w - s * (x1 - x0)) / 2;
    const oy = (h - s * (y1 - y0)) / 2;
    return [(x) => ox + s * (x - x0), (y) => h - oy - s * (y - y0), s];
  }

  draw(vertices, f, time) {
    const ctx = this.ctx;
    const [X, Y] = this._transform();
    ctx.fillStyle = this.data.section.background;
    ctx.fillRect(0, 0, this.canvas.width, this.canvas.height);
    ctx.lineWidth = 1.5;
    for (const [name, faces] of Object.entries(this.data.mesh.parts)) {
      if (this.hidden && this.hidden.has(name)) continue;
      ctx.strokeStyle = this.data.section.colours[name];
      ctx.beginPath();
      cutTriangles(vertices, faces, (ax, ay, bx, by) => {
        ctx.moveTo(X(ax), Y(ay));
        ctx.lineTo(X(bx), Y(by));
      });
      ctx.stroke();
    }
    ctx.setLineDash([4, 3]);
    ctx.strokeStyle = "#555";
    for (const trace of Object.values(this.data.section.traces)) {
      ctx.beginPath();
      for (let i = 0; i < trace.length; i += 2) {
        const move = i === 0 ? "moveTo" : "lineTo";
        ctx[move](X(trace[i]), Y(trace[i + 1]));
      }
      ctx.stroke();
    }
    ctx.setLineDash([]);
    this._pellets(f, X, Y);
    ctx.fillStyle = "#222";
    ctx.font = "12px sans-serif";
    ctx.fillText(`midsagittal   t = ${time.toFixed(3)} s`, 6, 14);
  }

  _pellets(f, X, Y) {
    const ctx = this.ctx;
    const p = this.data.pellets;
    const n = p.names.length;
    const at = (arr, g, j) => [arr[2 * (g * n + j)], arr[2 * (g * n + j) + 1]];
    for (let j = 0; j < n; j++) {
      if (!p.shown[j]) continue;
      if (this.showMeasured !== false) {
        ctx.strokeStyle = "#e61414";
        ctx.beginPath();
        let started = false;
        for (let g = Math.max(0, f - p.trail_frames + 1); g <= f; g++) {
          const [x, y] = at(p.measured, g, j);
          if (!Number.isFinite(x) || !Number.isFinite(y)) continue;
          ctx[started ? "lineTo" : "moveTo"](X(x), Y(y));
          started = true;
        }
        ctx.stroke();
        dot(ctx, at(p.measured, f, j), X, Y, "#e61414", p.names[j]);
      }
      if (this.showModel !== false) dot(ctx, at(p.model, f, j), X, Y, "#1ab838", null);
    }
  }
}

function dot(ctx, [x, y], X, Y, colour, name) {
  if (!Number.isFinite(x) || !Number.isFinite(y)) return;
  ctx.fillStyle = colour;
  ctx.beginPath();
  ctx.arc(X(x), Y(y), 3.5, 0, 2 * Math.PI);
  ctx.fill();
  if (name) {
    ctx.font = "10px sans-serif";
    ctx.fillText(name, X(x) + 5, Y(y) - 5);
  }
}

// Call segment(ax, ay, bx, by) for each triangle crossing z = 0.
export function cutTriangles(v, faces, segment) {
  const pts = [0, 0, 0, 0];
  for (let t = 0; t < faces.length; t += 3) {
    let count = 0;
    for (let e = 0; e < 3; e++) {
      const a = 3 * faces[t + e];
      const b = 3 * faces[t + ((e + 1) % 3)];
      const za = v[a + 2];
      const zb = v[b + 2];
      if ((za < 0) === (zb < 0) || count === 4) continue;
      const s = za / (za - zb);
      pts[count++] = v[a] + s * (v[b] - v[a]);
      pts[count++] = v[a + 1] + s * (v[b + 1] - v[a + 1]);
    }
    if (count === 4) segment(pts[0], pts[1], pts[2], pts[3]);
  }
}
