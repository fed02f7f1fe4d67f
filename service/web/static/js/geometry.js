// Geometry for display: decoding POST /v1/info?preview=true, the result's JSON, deviations,
// and decimation for display only (the computation always uses every point).

// What is drawn at most (vertices; triangles): with a GPU, and with a software renderer
// (SwiftShader, llvmpipe: headless browsers, machines without a GPU), where every pixel costs CPU.
export const BUDGETS = { gpu: [300000, 600000], software: [60000, 120000] };
let [DISPLAY_MAX_POINTS, DISPLAY_MAX_FACES] = BUDGETS.gpu;

/** Choose the display budget ("gpu" or "software"). */
export function setDisplayBudget(kind) {
  [DISPLAY_MAX_POINTS, DISPLAY_MAX_FACES] = BUDGETS[kind] || BUDGETS.gpu;
}

function fromBase64(text, Type) {
  if (!text) return null;
  const bin = atob(text);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return new Type(bytes.buffer);
}

/** {origin, n, dimension, positions (Float32 n*3, relative to origin), faces, segments}. */
export function decodePreview(preview) {
  return {
    origin: preview.origin,
    n: preview.n_points,
    dimension: preview.dimension,
    positions: fromBase64(preview.positions, Float32Array),
    faces: fromBase64(preview.faces, Uint32Array),
    segments: fromBase64(preview.segments, Uint32Array),
  };
}

/** Points of a result in the JSON format, relative to `origin`, as Float32 n*3. */
export function resultPositions(json, origin) {
  const pts = json.points;
  const out = new Float32Array(pts.length * 3);
  for (let i = 0; i < pts.length; i++) {
    const p = pts[i];
    for (let d = 0; d < 3 && d < p.length; d++) out[3 * i + d] = p[d] - origin[d];
  }
  return out;
}

/** ||x_i - p_i|| in data units for every point (first three coordinates). */
export function deviations(before, after) {
  const n = before.length / 3;
  const out = new Float32Array(n);
  for (let i = 0; i < n; i++) {
    const dx = after[3 * i] - before[3 * i];
    const dy = after[3 * i + 1] - before[3 * i + 1];
    const dz = after[3 * i + 2] - before[3 * i + 2];
    out[i] = Math.sqrt(dx * dx + dy * dy + dz * dz);
  }
  return out;
}

function bounds(pos) {
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < pos.length; i += 3) {
    for (let d = 0; d < 3; d++) { const v = pos[i + d]; if (v < lo[d]) lo[d] = v; if (v > hi[d]) hi[d] = v; }
  }
  return { lo, hi };
}

/** Vertex clustering on an r^3 grid: cluster id per vertex, representative per cluster. */
function cluster(pos, r) {
  const { lo, hi } = bounds(pos);
  const size = hi.map((h, d) => Math.max(h - lo[d], 1e-30) / r);
  const n = pos.length / 3;
  const ids = new Map();
  const of = new Uint32Array(n);
  const keep = [];
  for (let i = 0; i < n; i++) {
    let key = 0;
    for (let d = 2; d >= 0; d--) key = key * (r + 1) + Math.min(r, Math.floor((pos[3 * i + d] - lo[d]) / size[d]));
    let id = ids.get(key);
    if (id === undefined) { id = keep.length; ids.set(key, id); keep.push(i); }
    of[i] = id;
  }
  return { of, keep: Uint32Array.from(keep) };
}

function remap(cells, of, width) {
  if (!cells) return null;
  const out = new Uint32Array(cells.length);
  const seen = new Set(); // segments only: a * 2^26 + b stays an exact integer
  let m = 0;
  for (let c = 0; c < cells.length; c += width) {
    const a = of[cells[c]], b = of[cells[c + 1]], z = width === 3 ? of[cells[c + 2]] : -1;
    if (a === b || a === z || b === z) continue; // collapsed into one cluster
    if (width === 2) {
      const key = Math.min(a, b) * 67108864 + Math.max(a, b);
      if (seen.has(key)) continue;
      seen.add(key);
    }
    out[m++] = a; out[m++] = b;
    if (width === 3) out[m++] = z;
  }
  return out.slice(0, m);
}

/**
 * How to draw `geom` within the display budget. Returns {keep, of, faces, segments, decimated}
 * where keep[k] is the original index of displayed vertex k and of[i] the displayed vertex of i.
 * Meshes and curves: vertex clustering (connectivity remapped); clouds: every s-th point.
 */
export function displayPlan(geom) {
  const n = geom.n;
  const nFaces = geom.faces ? geom.faces.length / 3 : 0;
  if (n <= DISPLAY_MAX_POINTS && nFaces <= DISPLAY_MAX_FACES) {
    const keep = new Uint32Array(n).map((_, i) => i);
    return { keep, of: keep, faces: geom.faces, segments: geom.segments, decimated: false };
  }
  if (!geom.faces && !geom.segments) {
    const s = Math.ceil(n / DISPLAY_MAX_POINTS);
    const keep = new Uint32Array(Math.ceil(n / s)).map((_, k) => k * s);
    const of = new Uint32Array(n).map((_, i) => Math.floor(i / s));
    return { keep, of, faces: null, segments: null, decimated: true };
  }
  // Surfaces occupy ~2 r^2 cells of an r^3 grid; shrink r until the budget holds.
  let r = Math.max(8, Math.floor(Math.sqrt(Math.min(DISPLAY_MAX_POINTS, DISPLAY_MAX_FACES / 2) / 2)));
  for (let attempt = 0; attempt < 8; attempt++, r = Math.floor(r * 0.75)) {
    const { of, keep } = cluster(geom.positions, r);
    const faces = remap(geom.faces, of, 3);
    if (keep.length <= DISPLAY_MAX_POINTS && (!faces || faces.length / 3 <= DISPLAY_MAX_FACES)) {
      return { keep, of, faces, segments: remap(geom.segments, of, 2), decimated: true };
    }
  }
  throw new Error("cannot decimate this input for display");
}

/** Positions of the displayed vertices. */
export function take(positions, keep) {
  const out = new Float32Array(keep.length * 3);
  for (let k = 0; k < keep.length; k++) {
    const i = 3 * keep[k];
    out[3 * k] = positions[i]; out[3 * k + 1] = positions[i + 1]; out[3 * k + 2] = positions[i + 2];
  }
  return out;
}

/** Per displayed vertex: the largest deviation among the points it stands for. */
export function takeMax(values, of, count) {
  const out = new Float32Array(count);
  for (let i = 0; i < values.length; i++) if (values[i] > out[of[i]]) out[of[i]] = values[i];
  return out;
}
