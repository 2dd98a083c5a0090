// The page's data: the JSON block written by cassi_fit.viewer._data, its base64 arrays
// decoded, and the face's vertices of any frame rebuilt from the compact motion encoding
// (cassi_fit/viewer/_encode.py): rest + mean + sum_k coeff[f, k] * basis[k] over the
// moving vertices, both quantised to int16 with one scale per component.

const TYPES = {
  f4: Float32Array,
  f8: Float64Array,
  i2: Int16Array,
  i4: Int32Array,
  u1: Uint8Array,
  u2: Uint16Array,
  u4: Uint32Array,
};

export function decodeArray(entry) {
  const bytes = Uint8Array.from(atob(entry.b64), (c) => c.charCodeAt(0));
  const Type = TYPES[entry.dtype];
  return new Type(bytes.buffer, 0, bytes.byteLength / Type.BYTES_PER_ELEMENT);
}

export function readData(id) {
  const raw = JSON.parse(document.getElementById(id).textContent);
  const out = {};
  const walk = (value) => {
    if (value && typeof value === "object" && !Array.isArray(value)) {
      if ("b64" in value && "dtype" in value) return decodeArray(value);
      const copy = {};
      for (const [key, item] of Object.entries(value)) copy[key] = walk(item);
      return copy;
    }
    return value;
  };
  Object.assign(out, walk(raw));
  return out;
}

export class Motion {
  // Vertices of frame f (Float32Array, V*3, model frame mm) from the encoded motion.
  constructor(mesh, motion) {
    this.rest = mesh.rest;
    this.moving = motion.moving;
    this.n = this.moving.length;
    this.k = motion.n_components;
    const width = 3 * this.n;
    this.mean = motion.mean;
    this.basis = new Float32Array(this.k * width);
    for (let c = 0; c < this.k; c++) {
      const s = motion.basis_scale[c];
      for (let i = 0; i < width; i++) this.basis[c * width + i] = motion.basis[c * width + i] * s;
    }
    this.coeff = motion.coeff;
    this.coeffScale = motion.coeff_scale;
    this.out = new Float32Array(this.rest);
    this.disp = new Float32Array(width);
  }

  frame(f) {
    const width = 3 * this.n;
    const disp = this.disp;
    disp.set(this.mean);
    for (let c = 0; c < this.k; c++) {
      const a = this.coeff[f * this.k + c] * this.coeffScale[c];
      if (a === 0) continue;
      const row = c * width;
      for (let i = 0; i < width; i++) disp[i] += a * this.basis[row + i];
    }
    const out = this.out;
    for (let j = 0; j < this.n; j++) {
      const v = 3 * this.moving[j];
      out[v] = this.rest[v] + disp[3 * j];
      out[v + 1] = this.rest[v + 1] + disp[3 * j + 1];
      out[v + 2] = this.rest[v + 2] + disp[3 * j + 2];
    }
    return out;
  }
}

// The frame shown at recording time t (s): the last frame whose time is at most t plus
// half a frame step, clamped to the recording.
export function frameAt(times, t) {
  let lo = 0;
  let hi = times.length - 1;
  if (!(t > times[0])) return 0;
  if (t >= times[hi]) return hi;
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (times[mid] <= t) lo = mid;
    else hi = mid;
  }
  return t - times[lo] < times[hi] - t ? lo : hi;
}
