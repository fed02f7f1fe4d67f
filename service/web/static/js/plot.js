// Small canvas plots: phi(lambda) on log-log axes with the tau line (report fig. 7), drawn as
// the lambda iterations arrive, and the filter factors gamma_i of eq. (12).

const COLORS = { axis: "#5d6677", grid: "#e6e9ef", curve: "#2459c4", tau: "#b3261e", last: "#1e7b34" };

function niceLogTicks(lo, hi) {
  const ticks = [];
  for (let e = Math.floor(Math.log10(lo)); e <= Math.ceil(Math.log10(hi)); e++) ticks.push(10 ** e);
  return ticks;
}

function niceLinearTicks(lo, hi, count = 5) {
  const raw = (hi - lo) / count;
  const mag = 10 ** Math.floor(Math.log10(raw || 1));
  const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= raw) || raw;
  const ticks = [];
  for (let t = Math.ceil(lo / step) * step; t <= hi + step * 1e-9; t += step) ticks.push(Number(t.toPrecision(12)));
  return ticks;
}

function fmt(v) {
  if (v === null || v === undefined || !Number.isFinite(v)) return "–";
  const a = Math.abs(v);
  return a !== 0 && (a < 1e-3 || a >= 1e4) ? v.toExponential(2) : String(Number(v.toPrecision(4)));
}

function setup(canvas) {
  const ratio = window.devicePixelRatio || 1;
  const w = canvas.clientWidth || canvas.width;
  const h = Math.round((w * canvas.height) / canvas.width) || canvas.height;
  if (canvas.width !== Math.round(w * ratio)) {
    canvas.style.height = `${h}px`;
    canvas.dataset.h = h;
    canvas.width = Math.round(w * ratio);
    canvas.height = Math.round(h * ratio);
  }
  const ctx = canvas.getContext("2d");
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  const height = Number(canvas.dataset.h) || canvas.height / ratio;
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.font = "11px system-ui, sans-serif";
  return { ctx, w: canvas.width / ratio, h: height };
}

/** Axes box with log or linear scales; returns the mapping functions. */
function axes(ctx, box, xr, yr, { xlog, ylog, xlabel, ylabel }) {
  const tx = xlog ? Math.log10 : (v) => v;
  const ty = ylog ? Math.log10 : (v) => v;
  const [x0, x1] = xr.map(tx);
  const [y0, y1] = yr.map(ty);
  const X = (v) => box.l + ((tx(v) - x0) / (x1 - x0 || 1)) * (box.r - box.l);
  const Y = (v) => box.b - ((ty(v) - y0) / (y1 - y0 || 1)) * (box.b - box.t);
  ctx.strokeStyle = COLORS.grid;
  ctx.fillStyle = COLORS.axis;
  ctx.lineWidth = 1;
  const xt = xlog ? niceLogTicks(...xr) : niceLinearTicks(...xr);
  const yt = ylog ? niceLogTicks(...yr) : niceLinearTicks(...yr, 4);
  ctx.textAlign = "center";
  for (const t of xt.filter((t) => t >= xr[0] * 0.999 && t <= xr[1] * 1.001)) {
    ctx.beginPath(); ctx.moveTo(X(t), box.t); ctx.lineTo(X(t), box.b); ctx.stroke();
    ctx.fillText(fmt(t), X(t), box.b + 14);
  }
  ctx.textAlign = "right";
  for (const t of yt.filter((t) => t >= yr[0] * 0.999 && t <= yr[1] * 1.001)) {
    ctx.beginPath(); ctx.moveTo(box.l, Y(t)); ctx.lineTo(box.r, Y(t)); ctx.stroke();
    ctx.fillText(fmt(t), box.l - 4, Y(t) + 4);
  }
  ctx.strokeStyle = COLORS.axis;
  ctx.strokeRect(box.l, box.t, box.r - box.l, box.b - box.t);
  ctx.textAlign = "center";
  ctx.fillText(xlabel, (box.l + box.r) / 2, box.b + 28);
  ctx.save(); ctx.translate(12, (box.t + box.b) / 2); ctx.rotate(-Math.PI / 2);
  ctx.fillText(ylabel, 0, 0); ctx.restore();
  return { X, Y };
}

function logRange(values, pad = 0.15) {
  const v = values.filter((x) => x > 0 && Number.isFinite(x));
  if (!v.length) return [0.1, 10];
  let lo = Math.min(...v), hi = Math.max(...v);
  if (hi / lo < 10) { const m = Math.sqrt(lo * hi); lo = m / 3.2; hi = m * 3.2; }
  const span = Math.log10(hi / lo) * pad;
  return [lo / 10 ** span, hi * 10 ** span];
}

export class PhiPlot {
  constructor(canvas) {
    this.canvas = canvas;
    this.reset();
  }

  reset() {
    this.points = []; // {iteration, lam, phi}
    this.tau = null;
    this.final = false;
    this.empty = null;
    this.draw();
  }

  setTau(tau) { if (tau > 0 && tau !== this.tau) { this.tau = tau; this.draw(); } }

  /** One lambda iteration (ignored if it is already drawn). */
  add(iteration, lam, phi) {
    if (!(lam > 0) || !(phi > 0) || this.points.some((p) => p.iteration === iteration)) return;
    this.points.push({ iteration, lam, phi });
    this.points.sort((a, b) => a.iteration - b.iteration);
    this.draw();
  }

  /**
   * The report's complete history (every lambda tried): the final picture. `empty` is what a
   * finished job with no lambda to draw says instead (e.g. returned unchanged).
   */
  finish(history, tau, empty = "this job tried no λ") {
    history.forEach((h, i) => this.add(i + 1, h.lambda, h.phi));
    if (tau > 0) this.tau = tau;
    this.final = true;
    this.empty = empty;
    this.draw();
  }

  draw() {
    const { ctx, w, h } = setup(this.canvas);
    const box = { l: 62, r: w - 14, t: 12, b: h - 36 };
    const lams = this.points.map((p) => p.lam);
    const phis = this.points.map((p) => p.phi).concat(this.tau ? [this.tau] : []);
    const { X, Y } = axes(ctx, box, logRange(lams), logRange(phis), { xlog: true, ylog: true, xlabel: "λ", ylabel: "φ(λ)" });
    if (this.tau) {
      ctx.setLineDash([6, 4]); ctx.strokeStyle = COLORS.tau;
      ctx.beginPath(); ctx.moveTo(box.l, Y(this.tau)); ctx.lineTo(box.r, Y(this.tau)); ctx.stroke();
      ctx.setLineDash([]); ctx.fillStyle = COLORS.tau; ctx.textAlign = "left";
      ctx.fillText(`τ = ${fmt(this.tau)}`, box.l + 6, Y(this.tau) - 5);
    }
    // phi is monotone in lambda: the points sorted by lambda trace the curve of fig. 7.
    const byLam = [...this.points].sort((a, b) => a.lam - b.lam);
    ctx.strokeStyle = COLORS.curve; ctx.lineWidth = 1.5;
    ctx.beginPath();
    byLam.forEach((p, i) => (i ? ctx.lineTo(X(p.lam), Y(p.phi)) : ctx.moveTo(X(p.lam), Y(p.phi))));
    ctx.stroke();
    const last = this.points[this.points.length - 1];
    for (const p of this.points) {
      ctx.fillStyle = p === last ? COLORS.last : COLORS.curve;
      ctx.beginPath(); ctx.arc(X(p.lam), Y(p.phi), p === last ? 5 : 3.5, 0, 2 * Math.PI); ctx.fill();
      ctx.fillStyle = COLORS.axis; ctx.textAlign = "left";
      ctx.fillText(String(p.iteration), X(p.lam) + 6, Y(p.phi) + 12);
    }
    if (!this.points.length) {
      ctx.fillStyle = COLORS.axis; ctx.textAlign = "center";
      const idle = this.tau ? "waiting for the first λ…" : "submit a job to see φ(λ) converge to τ";
      ctx.fillText(this.final ? this.empty : idle, (box.l + box.r) / 2, (box.t + box.b) / 2);
    }
    const c = this.canvas.dataset;
    c.iterations = String(this.points.length);
    c.lastIteration = last ? String(last.iteration) : "0";
    c.final = String(this.final);
    c.message = this.points.length ? "" : (this.final ? this.empty : "");
  }
}

/** gamma_i against i (linear axes; gamma in [0, 1]). */
export function drawSpectrum(canvas, gamma) {
  const { ctx, w, h } = setup(canvas);
  const box = { l: 52, r: w - 14, t: 12, b: h - 36 };
  const n = gamma.length;
  const { X, Y } = axes(ctx, box, [1, Math.max(2, n)], [0, 1], { xlog: false, ylog: false, xlabel: "i", ylabel: "γᵢ" });
  ctx.strokeStyle = COLORS.curve; ctx.lineWidth = 1.5; ctx.beginPath();
  gamma.forEach((g, i) => (i ? ctx.lineTo(X(i + 1), Y(g)) : ctx.moveTo(X(i + 1), Y(g))));
  ctx.stroke();
  canvas.dataset.points = String(n);
}

export { fmt };
